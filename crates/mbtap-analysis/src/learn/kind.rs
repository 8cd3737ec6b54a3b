//! What a guess says a register (or a run of them) holds, and the guess itself: the types
//! [`super::infer`] and [`super::layout`] both give.

/// The type a guess gives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Kind {
    /// Never changed while heard.
    Constant,
    /// Only counts up (and wraps at 65 536).
    Counter,
    /// A few distinct small values: the values seen.
    Enum(Vec<u16>),
    /// Changes flip single bits: the bits that ever changed.
    Bits(u16),
    /// A signed 16-bit value: it wraps around zero.
    I16,
    /// Any other 16-bit value.
    U16,
    /// Two registers: an unsigned 32-bit value (`counter` when it only grew).
    U32 { high_first: bool, counter: bool },
    /// Two registers: a signed 32-bit value.
    I32 { high_first: bool },
    /// Two registers: an IEEE-754 float.
    F32 { high_first: bool },
    /// A run of registers holding text, two characters each.
    Text { registers: u16, text: String },
}

impl Kind {
    /// Registers this guess covers.
    #[must_use]
    pub fn width(&self) -> u16 {
        match self {
            Self::U32 { .. } | Self::I32 { .. } | Self::F32 { .. } => 2,
            Self::Text { registers, .. } => *registers,
            _ => 1,
        }
    }

    /// A short stable name (`f32 low word first`), for text and JSON.
    #[must_use]
    pub fn name(&self) -> String {
        let order = |h: bool| if h { "high word first" } else { "low word first" };
        match self {
            Self::Constant => "constant".into(),
            Self::Counter => "counter".into(),
            Self::Enum(_) => "enum".into(),
            Self::Bits(_) => "bits".into(),
            Self::I16 => "i16".into(),
            Self::U16 => "u16".into(),
            Self::U32 { high_first, counter } => {
                format!("{} {}", if *counter { "u32 counter" } else { "u32" }, order(*high_first))
            }
            Self::I32 { high_first } => format!("i32 {}", order(*high_first)),
            Self::F32 { high_first } => format!("f32 {}", order(*high_first)),
            Self::Text { .. } => "string".into(),
        }
    }
}

/// One guess: where, what, how sure, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Guess {
    pub address: u16,
    pub kind: Kind,
    /// 0–1: how much evidence there was (samples and changes).
    pub confidence: f64,
    pub evidence: String,
}
