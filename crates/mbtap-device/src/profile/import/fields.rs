//! The columns a register sheet may have, and the header texts (English, German, Chinese)
//! that name each — the vocabulary [`super::sheet`] reads a header row with.

use super::notation::{norm, unit_from_name};

/// A column a sheet may have.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Field {
    Address,
    Name,
    Type,
    Scale,
    Unit,
    Access,
    WordOrder,
    Table,
    Length,
    Description,
}

impl Field {
    pub(super) const ALL: [Self; 10] = [
        Self::Address,
        Self::Name,
        Self::Type,
        Self::Scale,
        Self::Unit,
        Self::Access,
        Self::WordOrder,
        Self::Table,
        Self::Length,
        Self::Description,
    ];

    /// The key in `--columns`.
    #[must_use]
    pub const fn key(self) -> &'static str {
        match self {
            Self::Address => "address",
            Self::Name => "name",
            Self::Type => "type",
            Self::Scale => "scale",
            Self::Unit => "unit",
            Self::Access => "access",
            Self::WordOrder => "word_order",
            Self::Table => "table",
            Self::Length => "length",
            Self::Description => "description",
        }
    }

    /// Header texts (normalised) that name this column.
    pub(super) const fn headers(self) -> &'static [&'static str] {
        match self {
            Self::Address => &[
                "address",
                "addr",
                "register",
                "register address",
                "reg",
                "reg addr",
                "modbus address",
                "start address",
                "starting address",
                "register number",
                "reg no",
                "adresse",
                "registeradresse",
                "register adresse",
                "寄存器地址",
                "地址",
                "寄存器",
            ],
            Self::Name => &[
                "name",
                "parameter",
                "parameter name",
                "register name",
                "signal",
                "signal name",
                "variable",
                "tag",
                "point",
                "point name",
                "item",
                "bezeichnung",
                "名称",
                "参数",
                "参数名称",
            ],
            Self::Type => &[
                "type",
                "data type",
                "datatype",
                "format",
                "data format",
                "value type",
                "datentyp",
                "typ",
                "数据类型",
                "类型",
            ],
            Self::Scale => &[
                "scale",
                "scaling",
                "factor",
                "scale factor",
                "multiplier",
                "gain",
                "resolution",
                "faktor",
                "skalierung",
                "倍率",
                "系数",
            ],
            Self::Unit => &["unit", "units", "uom", "unit of measure", "einheit", "单位"],
            Self::Access => &[
                "access",
                "r/w",
                "rw",
                "read/write",
                "mode",
                "permission",
                "access type",
                "zugriff",
                "读写",
                "读写属性",
            ],
            Self::WordOrder => &["word order", "byte order", "endianness", "endian", "swap", "reihenfolge"],
            Self::Table => &[
                "table",
                "function",
                "function code",
                "fc",
                "register type",
                "area",
                "object type",
                "功能码",
                "funktion",
            ],
            Self::Length => &[
                "length",
                "size",
                "registers",
                "count",
                "quantity",
                "number of registers",
                "words",
                "no of registers",
                "länge",
                "长度",
                "数量",
            ],
            Self::Description => {
                &["description", "comment", "comments", "notes", "remark", "beschreibung", "说明", "备注", "描述"]
            }
        }
    }

    pub(super) fn parse_key(k: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.key() == norm(k).replace(' ', "_"))
    }
}

/// The field a header cell names, if any. A unit in the header (`Scale [x]`) is ignored.
pub(super) fn field_of(cell: &str) -> Option<Field> {
    let (text, _) = unit_from_name(cell);
    let n = norm(&text);
    let n = n.trim_end_matches([':', '.']);
    if n.is_empty() {
        return None;
    }
    let exact = |n: &str| Field::ALL.into_iter().find(|f| f.headers().contains(&n));
    // `Address (Register)`, `Scale [x]`: the words before a bracket.
    let before_bracket = n.split(['(', '[']).next().unwrap_or("").trim();
    exact(n).or_else(|| exact(before_bracket)).or_else(|| address_like(before_bracket).then_some(Field::Address))
}

/// Words that, in a header ending with "address", name the device rather than the register
/// (`Slave Address`, `IP address`, `通讯地址`).
const NOT_REGISTER: [&str; 12] =
    ["slave", "device", "unit", "station", "node", "server", "ip", "mac", "geräte", "通讯", "从站", "设备"];

/// A header naming a register's address in words the list does not hold (`Input
/// Register Address`, `PDU address`, `Modbus-Adresse`): its last word is an address, and no
/// word says it is a device's.
fn address_like(n: &str) -> bool {
    let words: Vec<&str> = n.split([' ', '/']).filter(|w| !w.is_empty()).collect();
    let Some(last) = words.last() else { return false };
    let address = matches!(*last, "address" | "addr" | "adr" | "adresse" | "adress")
        || last.ends_with("adresse")
        || last.ends_with("地址");
    address && !words.iter().any(|w| NOT_REGISTER.iter().any(|x| w.starts_with(x)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Input Register Address` and other wordings of the register's address name an address
    /// column; a device's address does not.
    #[test]
    fn headers_naming_a_registers_address_in_other_words() {
        for h in [
            "Input Register Address",
            "Holding register address (dec)",
            "PDU address",
            "Modbus-Adresse",
            "Register Addr.",
            "起始地址",
        ] {
            assert_eq!(field_of(h), Some(Field::Address), "{h}");
        }
        for h in ["Slave Address", "IP address", "Device address", "通讯地址", "Unit addr"] {
            assert_eq!(field_of(h), None, "{h}");
        }
        assert_eq!(field_of("Start Address"), Some(Field::Address));
    }
}
