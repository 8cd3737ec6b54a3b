//! The four tables of the Modbus data model (MAP v1.1b3 §4.3: discrete inputs, coils, input
//! registers, holding registers), the words users type for them, and the read function code of
//! each (MAP v1.1b3 §6.1–§6.4). The profile format, the query planner and the gateway's cache
//! all speak of tables through this one type.

/// Which table of the data model an address is in (MAP v1.1b3 §4.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Table {
    Coils,
    DiscreteInputs,
    HoldingRegisters,
    InputRegisters,
}

impl Table {
    /// The table's name in profiles and JSON (`holding_registers`, …).
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Coils => "coils",
            Self::DiscreteInputs => "discrete_inputs",
            Self::HoldingRegisters => "holding_registers",
            Self::InputRegisters => "input_registers",
        }
    }

    /// The table word users type (`holding`, `input`, `coil`, `discrete`).
    #[must_use]
    pub const fn word(self) -> &'static str {
        match self {
            Self::Coils => "coil",
            Self::DiscreteInputs => "discrete",
            Self::HoldingRegisters => "holding",
            Self::InputRegisters => "input",
        }
    }
}

/// The table words users type, and the table each means.
pub const TABLE_WORDS: &[(&str, Table)] = &[
    ("coils", Table::Coils),
    ("coil", Table::Coils),
    ("discrete", Table::DiscreteInputs),
    ("discrete_inputs", Table::DiscreteInputs),
    ("holding", Table::HoldingRegisters),
    ("holding_registers", Table::HoldingRegisters),
    ("input", Table::InputRegisters),
    ("input_registers", Table::InputRegisters),
];

/// The table a word names, if it names one (any case).
#[must_use]
pub fn table_word(word: &str) -> Option<Table> {
    TABLE_WORDS.iter().find(|(w, _)| w.eq_ignore_ascii_case(word)).map(|&(_, t)| t)
}

/// The function code that reads `table` (MAP v1.1b3 §6.1–§6.4).
#[must_use]
pub const fn read_function(table: Table) -> u8 {
    match table {
        Table::Coils => 0x01,
        Table::DiscreteInputs => 0x02,
        Table::HoldingRegisters => 0x03,
        Table::InputRegisters => 0x04,
    }
}

/// The table a read function code reads, when it is one (MAP v1.1b3 §6.1–§6.4).
#[must_use]
pub const fn table_read_by(function: u8) -> Option<Table> {
    match function {
        0x01 => Some(Table::Coils),
        0x02 => Some(Table::DiscreteInputs),
        0x03 => Some(Table::HoldingRegisters),
        0x04 => Some(Table::InputRegisters),
        _ => None,
    }
}

/// Whether a table holds bits (coils, discrete inputs) rather than 16-bit registers.
#[must_use]
pub const fn is_bits(table: Table) -> bool {
    matches!(table, Table::Coils | Table::DiscreteInputs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_tables_read_function_reads_that_table_back() {
        for (_, table) in TABLE_WORDS {
            assert_eq!(table_read_by(read_function(*table)), Some(*table));
            assert_eq!(table_word(table.word()), Some(*table));
            assert_eq!(table_word(table.name()), Some(*table));
        }
        assert_eq!(table_read_by(0x05), None);
        assert_eq!(table_word("HOLDING"), Some(Table::HoldingRegisters));
    }
}
