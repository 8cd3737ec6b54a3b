//! What the commands share and no one command owns: the options several take ([`args`]) and the
//! one runner of the analyzing commands ([`runner`]). The commands themselves are in `cmd/`.
//!
//! [`numbers`] checks numeric option values once, where clap reads them.

pub mod args;
pub mod numbers;
pub mod runner;
