//! A remote serial port over Telnet with the COM-PORT-OPTION (RFC 2217), as ser2net and
//! Moxa NPort servers offer it (`--serial rfc2217://HOST:PORT`): the bridge sets the remote
//! line's baud rate, data bits, parity and stop bits, and the line's bytes travel in Telnet's
//! binary mode (RFC 856), every `FF` doubled (RFC 854). Sans-IO: [`Telnet::greeting`] and
//! [`Telnet::escape`] give what to send, [`Telnet::feed`] splits what was received into the
//! line's bytes and the answers Telnet requires. Bounded: a subnegotiation's content is skipped,
//! not stored.

use crate::serial_line::{LineSettings, Parity};

/// Telnet commands (RFC 854).
const IAC: u8 = 255;
const DONT: u8 = 254;
const DO: u8 = 253;
const WONT: u8 = 252;
const WILL: u8 = 251;
const SB: u8 = 250;
const SE: u8 = 240;
/// Carriage return: NVT sends a bare one as CR NUL (RFC 854).
const CR: u8 = 0x0D;
/// Options: binary transmission (RFC 856), suppress go-ahead (RFC 858), COM port (RFC 2217).
const BINARY: u8 = 0;
const SGA: u8 = 3;
const COM_PORT_OPTION: u8 = 44;
/// COM-PORT-OPTION client commands (RFC 2217 §3).
const SET_BAUDRATE: u8 = 1;
const SET_DATASIZE: u8 = 2;
const SET_PARITY: u8 = 3;
const SET_STOPSIZE: u8 = 4;

/// The SET-PARITY value of `parity` (RFC 2217 §3: 1 none, 2 odd, 3 even).
#[must_use]
pub const fn parity_code(parity: Parity) -> u8 {
    match parity {
        Parity::None => 1,
        Parity::Odd => 2,
        Parity::Even => 3,
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Data,
    Iac,
    /// After IAC and a verb (WILL, WONT, DO, DONT): the option byte is next.
    Verb(u8),
    /// After a CR on a stream the server sends as NVT text (it refused BINARY): a NUL next is
    /// the CR's padding (RFC 854: "CR NUL" is a bare CR), dropped.
    Cr,
    /// Inside a subnegotiation, skipped.
    Sub,
    SubIac,
}

/// One Telnet session's state.
#[derive(Debug, Clone)]
pub struct Telnet {
    setup: LineSettings,
    state: State,
    /// The server agreed to the COM port option and was sent the line's settings.
    pub configured: bool,
    /// Options refused once (not refused again: a server that repeats itself must not make a
    /// loop of answers).
    refused: [bool; 256],
    /// The server will not send in binary (WONT BINARY): what it sends is NVT text, a CR
    /// followed by NUL (RFC 854), undone here.
    pub nvt_in: bool,
    /// The server will not receive binary (DONT BINARY): a CR we send goes as CR NUL.
    pub nvt_out: bool,
}

impl Telnet {
    #[must_use]
    pub fn new(setup: LineSettings) -> Self {
        Self { setup, state: State::Data, configured: false, refused: [false; 256], nvt_in: false, nvt_out: false }
    }

    /// What the client says first: it will do the COM port option and binary both ways, and
    /// suppress go-ahead.
    #[must_use]
    pub fn greeting() -> Vec<u8> {
        vec![IAC, WILL, COM_PORT_OPTION, IAC, WILL, BINARY, IAC, DO, BINARY, IAC, WILL, SGA, IAC, DO, SGA]
    }

    /// The line's settings as COM-PORT-OPTION subnegotiations (sent once the server says
    /// DO COM-PORT-OPTION).
    fn settings(&self) -> Vec<u8> {
        let mut out = Vec::new();
        let mut sub = |command: u8, value: &[u8]| {
            out.extend_from_slice(&[IAC, SB, COM_PORT_OPTION, command]);
            out.extend(escape(value));
            out.extend_from_slice(&[IAC, SE]);
        };
        sub(SET_BAUDRATE, &self.setup.baud.to_be_bytes());
        sub(SET_DATASIZE, &[self.setup.data_bits]);
        sub(SET_PARITY, &[parity_code(self.setup.parity)]);
        sub(SET_STOPSIZE, &[self.setup.stop_bits]);
        out
    }

    /// The line's `bytes` as they go on the Telnet stream: every FF doubled (RFC 854), and a
    /// CR as CR NUL where the server refused binary reception (RFC 854's NVT; RFC 856).
    #[must_use]
    pub fn escape_out(&self, bytes: &[u8]) -> Vec<u8> {
        let mut out = escape(bytes);
        if self.nvt_out {
            let mut nvt = Vec::with_capacity(out.len() + 4);
            for b in out {
                nvt.push(b);
                if b == CR {
                    nvt.push(0);
                }
            }
            out = nvt;
        }
        out
    }

    /// Whether the server refused binary transmission in either direction.
    #[must_use]
    pub fn binary_refused(&self) -> bool {
        self.nvt_in || self.nvt_out
    }

    /// Takes what the server sent: the line's bytes are appended to `data`, what Telnet
    /// requires in answer to `reply`.
    pub fn feed(&mut self, received: &[u8], data: &mut Vec<u8>, reply: &mut Vec<u8>) {
        for &b in received {
            self.state = match (self.state, b) {
                (State::Cr, 0) => State::Data,
                (State::Data | State::Cr, IAC) => State::Iac,
                (State::Data | State::Cr, CR) if self.nvt_in => {
                    data.push(CR);
                    State::Cr
                }
                (State::Cr | State::Data, b) => {
                    data.push(b);
                    State::Data
                }
                (State::Iac, IAC) => {
                    data.push(IAC);
                    State::Data
                }
                (State::Iac, WILL | WONT | DO | DONT) => State::Verb(b),
                (State::Iac, SB) => State::Sub,
                (State::Verb(verb), option) => {
                    self.answer(verb, option, reply);
                    State::Data
                }
                (State::Sub, IAC) => State::SubIac,
                // NOP, GA, DM and the other one-byte commands: nothing to do; a subnegotiation
                // ends at IAC SE.
                (State::Iac, _) | (State::SubIac, SE) => State::Data,
                (State::Sub | State::SubIac, _) => State::Sub,
            };
        }
    }

    fn answer(&mut self, verb: u8, option: u8, reply: &mut Vec<u8>) {
        let ours = matches!(option, BINARY | SGA | COM_PORT_OPTION);
        match verb {
            // Our WILL acknowledged; the COM port option's settings follow at once (once).
            DO if option == COM_PORT_OPTION && !self.configured => {
                self.configured = true;
                reply.extend(self.settings());
            }
            DO if ours => {}
            DO => self.refuse(WONT, option, reply),
            // Our DO acknowledged (binary, go-ahead); anything else the server offers is declined.
            WILL if matches!(option, BINARY | SGA) => {}
            WILL => self.refuse(DONT, option, reply),
            // Binary refused (used anyway, and answers holding 0D came out wrong): the
            // stream is NVT text that way, its CR NUL undone or made.
            WONT if option == BINARY => self.nvt_in = true,
            DONT if option == BINARY => self.nvt_out = true,
            _ => {}
        }
    }

    fn refuse(&mut self, verb: u8, option: u8, reply: &mut Vec<u8>) {
        let seen = &mut self.refused[usize::from(option)];
        if !*seen {
            *seen = true;
            reply.extend_from_slice(&[IAC, verb, option]);
        }
    }
}

fn escape(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(bytes.len() + 2);
    for &b in bytes {
        out.push(b);
        if b == IAC {
            out.push(IAC);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const SETUP: LineSettings = LineSettings { baud: 9600, data_bits: 8, parity: Parity::Even, stop_bits: 1 };

    #[test]
    fn the_settings_go_out_when_the_server_agrees_to_the_com_port_option() {
        let mut t = Telnet::new(SETUP);
        let (mut data, mut reply) = (Vec::new(), Vec::new());
        // Server: DO COM-PORT-OPTION, WILL BINARY.
        t.feed(&[IAC, DO, COM_PORT_OPTION, IAC, WILL, BINARY], &mut data, &mut reply);
        assert!(data.is_empty() && t.configured);
        let want = [
            IAC, SB, 44, 1, 0x00, 0x00, 0x25, 0x80, IAC, SE, // SET-BAUDRATE 9600
            IAC, SB, 44, 2, 8, IAC, SE, // SET-DATASIZE 8
            IAC, SB, 44, 3, 3, IAC, SE, // SET-PARITY even
            IAC, SB, 44, 4, 1, IAC, SE, // SET-STOPSIZE 1
        ];
        assert_eq!(reply, want);
        // Said again: not sent again.
        reply.clear();
        t.feed(&[IAC, DO, COM_PORT_OPTION], &mut data, &mut reply);
        assert!(reply.is_empty());
    }

    #[test]
    fn ff_is_doubled_going_out_and_undoubled_coming_in_and_commands_are_not_data() {
        let mut t = Telnet::new(SETUP);
        assert_eq!(t.escape_out(&[0x01, 0xFF, 0x03]), [0x01, 0xFF, 0xFF, 0x03]);
        let (mut data, mut reply) = (Vec::new(), Vec::new());
        // 01 FF (doubled), a subnegotiation answer (skipped), NOP, 03 — in two reads split
        // inside the subnegotiation.
        t.feed(&[0x01, IAC, IAC, IAC, SB, 44, 101, 0, 0], &mut data, &mut reply);
        t.feed(&[0x25, 0x80, IAC, SE, IAC, 241, 0x03], &mut data, &mut reply);
        assert_eq!(data, [0x01, 0xFF, 0x03]);
        assert!(reply.is_empty());
    }

    /// A server refusing BINARY sends a CR as CR NUL: the NUL is padding, not a line byte, so
    /// answers holding 0D still check.
    #[test]
    fn a_server_refusing_binary_is_read_and_written_as_nvt() {
        let mut t = Telnet::new(SETUP);
        let (mut data, mut reply) = (Vec::new(), Vec::new());
        // Server: DO COM-PORT-OPTION, WONT BINARY, DONT BINARY.
        t.feed(&[IAC, DO, COM_PORT_OPTION, IAC, WONT, BINARY, IAC, DONT, BINARY], &mut data, &mut reply);
        assert!(t.binary_refused() && t.configured);
        // An answer 01 03 02 0D 0A + CRC, its CR as CR NUL, split between the CR and the NUL.
        t.feed(&[0x01, 0x03, 0x02, CR], &mut data, &mut reply);
        t.feed(&[0x00, 0x0A, CR, 0x00, 0x00], &mut data, &mut reply);
        assert_eq!(data, [0x01, 0x03, 0x02, CR, 0x0A, CR, 0x00]);
        assert_eq!(t.escape_out(&[0x01, CR, 0xFF]), [0x01, CR, 0x00, 0xFF, 0xFF]);
    }

    #[test]
    fn unknown_options_are_refused_once() {
        let mut t = Telnet::new(SETUP);
        let (mut data, mut reply) = (Vec::new(), Vec::new());
        // Server: WILL ECHO (1), DO TERMINAL-TYPE (24), and WILL ECHO again.
        t.feed(&[IAC, WILL, 1, IAC, DO, 24, IAC, WILL, 1], &mut data, &mut reply);
        assert_eq!(reply, [IAC, DONT, 1, IAC, WONT, 24]);
        assert!(data.is_empty());
    }
}
