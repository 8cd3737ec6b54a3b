//! Who waits in a line's queue: every asker gets its queue id here, so no two askers share
//! one and the line can tell its own polls from a client's requests. Connections (TCP, TLS,
//! RTU over TCP) and UDP peers count up in ranges of their own; the askers there is one of per
//! line (the serial front, mbtap's own master, the broker's writes, the bridge's polls) have
//! fixed ids above every counter.

use std::sync::atomic::{AtomicU64, Ordering};

use crate::queue::ClientId;

/// The serial front's id (`--listen-serial`, reverse mode): one master on that port.
pub const SERIAL_FRONT: ClientId = 1 << 56;
/// mbtap's own master (`read`, `write`, `watch`, `probe`, the mirror): one per line it opens.
pub const MASTER: ClientId = SERIAL_FRONT + 1;
/// The broker's writes (`--mqtt-writes`): a client of their own, taking their turn.
pub const BROKER: ClientId = ClientId::MAX - 1;
/// The bridge's own polls (`--poll`): they take their turn like any client, so polling never
/// starves the clients' requests.
pub const POLL: ClientId = ClientId::MAX;

/// Where UDP peers' ids begin: apart from the connections' (2⁴⁸ connections are never accepted
/// in one run).
const FIRST_UDP_PEER: ClientId = 1 << 48;

static NEXT_CONNECTION: AtomicU64 = AtomicU64::new(1);
static NEXT_UDP_PEER: AtomicU64 = AtomicU64::new(FIRST_UDP_PEER);

/// A new connection's id (TCP, TLS, RTU over TCP).
#[must_use]
pub fn connection() -> ClientId {
    NEXT_CONNECTION.fetch_add(1, Ordering::Relaxed)
}

/// A new UDP peer's id.
#[must_use]
pub fn udp_peer() -> ClientId {
    NEXT_UDP_PEER.fetch_add(1, Ordering::Relaxed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_asker_has_an_id_of_its_own() {
        let (a, b) = (connection(), connection());
        let u = udp_peer();
        assert_ne!(a, b);
        for id in [a, b, u] {
            assert!(![SERIAL_FRONT, MASTER, BROKER, POLL].contains(&id));
        }
        assert!(a < FIRST_UDP_PEER && (FIRST_UDP_PEER..SERIAL_FRONT).contains(&u));
    }
}
