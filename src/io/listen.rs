//! Listening addresses as users type them: the one reading of `--listen`, `--listen-rtu`,
//! `--listen-udp`, `--listen-tls`, `--metrics` and `--serve`.

/// A listening address as users type it: `:PORT` is every interface (`0.0.0.0:PORT`, as
/// `ss`, Go and most servers read it); anything else is kept as given.
#[must_use]
pub fn bind_addr(addr: &str) -> String {
    if addr.starts_with(':') { format!("0.0.0.0{addr}") } else { addr.to_owned() }
}

#[cfg(test)]
mod tests {
    use super::bind_addr;

    #[test]
    fn a_bare_port_listens_on_every_interface_and_the_rest_stays_as_typed() {
        assert_eq!(bind_addr(":502"), "0.0.0.0:502");
        assert_eq!(bind_addr("127.0.0.1:0"), "127.0.0.1:0");
        assert_eq!(bind_addr("[::1]:502"), "[::1]:502");
        assert_eq!(bind_addr("localhost:1502"), "localhost:1502");
    }
}
