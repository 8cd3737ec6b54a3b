//! Who gives up a seat when a newcomer connects: the listeners' one decision about open
//! connections (plain, RTU over TCP and TLS share `--max-connections`). A client connects and
//! asks at once; a socket that has sent no whole request (a TLS handshake in progress counts) is
//! a silent one and goes first — one that never sent a byte before one that did, then the one
//! stalled longest (its last byte, or its opening, oldest) whatever its age — a flood of young silent sockets must not reset newcomers (500 of
//! them reset 20–55 %), and a handshake still under way outlasts sockets that stopped talking
//! (else the oldest silent socket is now and then a TLS client mid-handshake). Else the one idle
//! longest, if idle at least [`EVICT_AFTER_IDLE`]; a client that keeps asking is never evicted.
//! One source address may hold [`SILENT_PER_ADDRESS`] silent sockets. Time is an input (the
//! shell's clock since an origin it picks).

use std::net::IpAddr;
use std::time::Duration;

/// When every seat is taken, a connection that has sent no request for this long gives its seat
/// to the newcomer; one busier than that is never evicted.
pub const EVICT_AFTER_IDLE: Duration = Duration::from_secs(1);
/// Sockets one source address may hold open without having sent a whole request: a newcomer
/// from an address at the bound takes the seat of that address's oldest silent socket.
pub const SILENT_PER_ADDRESS: usize = 16;
/// A socket silent this long is idle: only then is it evicted for its address's bound (64
/// clients of one SCADA host connecting at once are all silent for a moment).
pub const SILENT_GRACE: Duration = Duration::from_millis(100);

/// One open connection as the decision sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Seat {
    /// The client's address, as [`crate::admit::canonical`] gives it.
    pub ip: IpAddr,
    pub opened: Duration,
    /// When it last sent a whole request; None: never.
    pub last_request: Option<Duration>,
    /// When it last sent any byte; None: never.
    pub last_byte: Option<Duration>,
}

impl Seat {
    /// Since when a silent seat has said nothing: its last byte, or its opening.
    fn stalled_since(&self) -> Duration {
        self.last_byte.unwrap_or(self.opened).max(self.opened)
    }

    /// The order silent seats go in: those that never sent a byte first, then the one stalled
    /// longest (a flood of fresh mute sockets is younger than a handshake waiting on its peer).
    fn eviction_key(&self) -> (bool, Duration) {
        (self.last_byte.is_some(), self.stalled_since())
    }
}

/// The seat `ip`'s newcomer takes for its address's bound: that address's silent seat (mute
/// before talking, then stalled longest), stalled at least [`SILENT_GRACE`], when it already holds [`SILENT_PER_ADDRESS`] silent ones.
pub fn for_address<'a, K: Copy + 'a>(
    seats: impl Iterator<Item = (K, &'a Seat)> + Clone,
    ip: IpAddr,
    now: Duration,
) -> Option<K> {
    let silent = seats.filter(|(_, s)| s.ip == ip && s.last_request.is_none());
    if silent.clone().count() < SILENT_PER_ADDRESS {
        return None;
    }
    silent
        .filter(|(_, s)| now.saturating_sub(s.stalled_since()) >= SILENT_GRACE)
        .min_by_key(|(_, s)| s.eviction_key())
        .map(|(k, _)| k)
}

/// The seat a newcomer takes when all are taken: a silent one (mute before talking, then stalled
/// longest), else the one
/// idle longest (at least [`EVICT_AFTER_IDLE`]); None: all are busy, the newcomer is refused.
pub fn for_room<'a, K: Copy + 'a>(seats: impl Iterator<Item = (K, &'a Seat)> + Clone, now: Duration) -> Option<K> {
    let silent = seats.clone().filter(|(_, s)| s.last_request.is_none()).min_by_key(|(_, s)| s.eviction_key());
    silent.map(|(k, _)| k).or_else(|| {
        seats
            .filter_map(|(k, s)| s.last_request.map(|l| (k, l)))
            .filter(|(_, l)| now.saturating_sub(*l) >= EVICT_AFTER_IDLE)
            .min_by_key(|(_, l)| *l)
            .map(|(k, _)| k)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    fn seat(ip: &str, opened: u64, last: Option<u64>) -> Seat {
        Seat { ip: ip.parse().unwrap(), opened: ms(opened), last_request: last.map(ms), last_byte: None }
    }

    /// (One address for the flood and the good clients.) A socket that is still talking — a TLS
    /// client mid-handshake — outlasts those that stalled, whatever their ages, never reset as the
    /// oldest silent socket.
    #[test]
    fn a_handshake_under_way_outlasts_sockets_that_stalled() {
        let handshaking = Seat { last_byte: Some(ms(99)), ..seat("127.0.0.1", 10, None) };
        let seats = [handshaking, seat("127.0.0.1", 40, None), seat("127.0.0.1", 60, None)];
        assert_eq!(for_room(seats.iter().enumerate(), ms(100)), Some(1), "the one stalled since 40 ms");
        // Waiting on its peer since 20 ms, it still outlasts a mute socket opened at 95 ms.
        let waiting = Seat { last_byte: Some(ms(20)), ..seat("127.0.0.1", 10, None) };
        let seats = [waiting, seat("127.0.0.1", 95, None)];
        assert_eq!(for_room(seats.iter().enumerate(), ms(100)), Some(1), "the mute one goes first");
        let half_hello = Seat { last_byte: Some(ms(30)), ..seat("127.0.0.1", 29, None) };
        let seats = [Seat { last_byte: Some(ms(60)), ..waiting }, half_hello];
        assert_eq!(for_room(seats.iter().enumerate(), ms(100)), Some(1), "stalled since 30 ms before 60 ms");
        let mut flood: Vec<Seat> = (0..16).map(|i| seat("127.0.0.1", 20 + i, None)).collect();
        flood.insert(0, handshaking);
        let ip = "127.0.0.1".parse().unwrap();
        assert_eq!(for_address(flood.iter().enumerate(), ip, ms(150)), Some(1));
    }

    /// Silent sockets younger than any grace cannot fill the table against every newcomer: the
    /// oldest silent one makes room, whatever its age.
    #[test]
    fn starve_the_oldest_silent_seat_makes_room_whatever_its_age() {
        let seats = [seat("10.0.0.1", 5, None), seat("10.0.0.1", 1, None), seat("10.0.0.2", 0, Some(9))];
        let pick = for_room(seats.iter().enumerate(), ms(10));
        assert_eq!(pick, Some(1));
        // All busy and none idle a second: refused.
        let busy = [seat("10.0.0.2", 0, Some(900))];
        assert_eq!(for_room(busy.iter().enumerate(), ms(1000)), None);
        assert_eq!(for_room(busy.iter().enumerate(), ms(1900)), Some(0));
    }

    #[test]
    fn an_address_holds_at_most_its_share_of_silent_seats_once_idle() {
        let mut seats: Vec<Seat> = (0..16).map(|i| seat("10.0.0.1", i, None)).collect();
        seats.push(seat("10.0.0.2", 0, None));
        let ip = "10.0.0.1".parse().unwrap();
        assert_eq!(for_address(seats.iter().enumerate(), ip, ms(50)), None, "none idle 100 ms yet");
        assert_eq!(for_address(seats.iter().enumerate(), ip, ms(200)), Some(0));
        assert_eq!(for_address(seats.iter().take(15).enumerate(), ip, ms(200)), None, "under the bound");
    }
}
