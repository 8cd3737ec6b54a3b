//! May this client do this? The admission policy every front (TCP, TLS, UDP, RTU over TCP, the
//! serial front and reverse mode, the MQTT broker's writes, the emulator's fronts) and mbtap's own
//! masters put each request through before it may reach a line: the request's length,
//! the client's role (MODBUS/TCP Security), read-only and function allow-lists, the rate limit,
//! the broadcast rule and the route. The answer is the serial address and route to queue on, or
//! a typed [`Refusal`] carrying the exception the client gets and the reason it is counted
//! under. Fails closed: a TLS client without a role, an unknown function under read-only, a
//! request of the wrong length — refused.

use std::collections::{BTreeMap, BTreeSet};
use std::net::IpAddr;
use std::ops::RangeInclusive;
use std::time::Duration;

use mbtap_proto::{ExceptionCode, request_len_problem};

use crate::BadValue;
use crate::parse::{parse_function_codes, parse_units};
use crate::rules::{
    GATEWAY_PATH_UNAVAILABLE, ILLEGAL_DATA_VALUE, ILLEGAL_FUNCTION, SERVER_DEVICE_BUSY, broadcastable,
    forwardable_length, read_only_safe,
};

/// Why a request was refused. Each is answered with an exception and counted under its
/// [`Refusal::reason`] (the `mbtap_bridge_refused_total{reason}` metric).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// Longer or shorter than its function allows: its extra bytes would reach the line as a
    /// frame of their own. 03.
    Malformed,
    /// A TLS client whose certificate carries no role, or a role no rule names. 01.
    NoRole,
    /// The client's role does not allow this function or unit. 01.
    Role,
    /// `--read-only`: not on the allow-list of what cannot change a device. 01.
    ReadOnly,
    /// Not among `--allow-function`. 01.
    FunctionNotAllowed,
    /// Over `--rate-limit`. 06.
    RateLimit,
    /// A broadcast (unit 0) that is not a write (Serial Line v1.02 §2.1). 01.
    BroadcastNotWrite,
    /// A broadcast (unit 0) without `--allow-broadcast`: it would change every device on the
    /// line at once (a broker client's `unit/0/…/set` did). 01.
    Broadcast,
    /// No `--route` serves the unit. 0A.
    NoRoute,
    /// The client has too many requests waiting. 06.
    QueueFull,
    /// The line has its bound of waiting requests, all clients together. 06.
    LineFull,
}

impl Refusal {
    /// The exception the client is answered with (MAP v1.1b3 §7).
    #[must_use]
    pub fn exception(self) -> ExceptionCode {
        match self {
            Self::Malformed => ILLEGAL_DATA_VALUE,
            Self::NoRole
            | Self::Role
            | Self::ReadOnly
            | Self::FunctionNotAllowed
            | Self::BroadcastNotWrite
            | Self::Broadcast => ILLEGAL_FUNCTION,
            Self::RateLimit | Self::QueueFull | Self::LineFull => SERVER_DEVICE_BUSY,
            Self::NoRoute => GATEWAY_PATH_UNAVAILABLE,
        }
    }

    /// The label it is counted under.
    #[must_use]
    pub fn reason(self) -> &'static str {
        match self {
            Self::Malformed => "malformed_request",
            Self::NoRole => "no_role",
            Self::Role => "role",
            Self::ReadOnly => "read_only",
            Self::FunctionNotAllowed => "function_not_allowed",
            Self::RateLimit => "rate_limit",
            Self::BroadcastNotWrite => "broadcast_not_write",
            Self::Broadcast => "broadcast",
            Self::NoRoute => "no_route",
            Self::QueueFull => "queue_full",
            Self::LineFull => "line_full",
        }
    }
}

/// What the listeners allow, parsed once from the command line and the configuration file.
#[derive(Debug, Clone, Default)]
pub struct Policy {
    /// Only requests that cannot change a device pass ([`read_only_safe`]).
    pub read_only: bool,
    /// Without `read_only`: only these function codes pass (None: all). With it: these pass
    /// too, on top of the read-only set — how a vendor read such as 0x46 is let through.
    pub allow_functions: Option<Vec<u8>>,
    /// TCP unit id → serial address.
    pub unit_map: BTreeMap<u8, u8>,
    /// `--priority high=…`: requests that go before the round-robin.
    pub priority: Vec<Priority>,
    /// Units served, per route (index = route number).
    pub routes: Vec<RangeInclusive<u8>>,
    /// `--allow-broadcast`: writes to unit 0 reach every device on the line. Off, they are
    /// refused whoever asks (fails closed).
    pub broadcast: bool,
}

/// Who the client is, for authorisation: anyone on a plain listener; on the TLS listener the
/// rules of its certificate's role, or none (no role, or one no rule names: nothing allowed);
/// the MQTT broker's writes (`--mqtt-writes`) under `--mqtt-role`'s rules, or the plain
/// listeners' where no `--role` exists (with roles, the bridge refuses to start without one).
#[derive(Debug, Clone, Copy)]
pub enum Role<'a> {
    Plain,
    Tls(Option<&'a RoleRules>),
    Broker(Option<&'a RoleRules>),
}

/// A request let through: where it goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Admitted {
    /// The serial address it reaches (after `--map-unit`).
    pub target: u8,
    /// The route's index in [`Policy::routes`].
    pub route: usize,
    /// In the priority class.
    pub high: bool,
}

/// One client's request as the listener read it.
#[derive(Debug, Clone, Copy)]
pub struct Asked<'a> {
    /// The unit id the client addressed.
    pub unit: u8,
    pub pdu: &'a [u8],
    pub role: Role<'a>,
    /// `--priority high=ip:…` matched the client's address.
    pub peer_high: bool,
}

impl Policy {
    /// Judges one request. `bucket`: the client's rate limiter, if `--rate-limit` is on; `now`:
    /// the caller's clock. Checks run in the order that keeps a refused request from costing
    /// anything: length, role, function rules, rate, broadcast, route.
    ///
    /// # Errors
    /// The [`Refusal`]; nothing of it reaches a line.
    pub fn admit(&self, asked: Asked<'_>, bucket: Option<&mut RateLimit>, now: Duration) -> Result<Admitted, Refusal> {
        let Asked { unit, pdu, role, peer_high } = asked;
        let function = pdu.first().copied().unwrap_or(0);
        if request_len_problem(pdu).is_some() || !forwardable_length(pdu) {
            return Err(Refusal::Malformed);
        }
        // The serial address the request will reach: roles and routes judge that, not the TCP
        // unit id (a role limited to units 2–20 must not reach unit 1 through --map-unit 10=1).
        let target = self.unit_map.get(&unit).copied().unwrap_or(unit);
        match role {
            Role::Tls(None) => return Err(Refusal::NoRole),
            Role::Tls(Some(r)) | Role::Broker(Some(r)) if !r.allows(target, pdu) => return Err(Refusal::Role),
            Role::Plain | Role::Tls(Some(_)) | Role::Broker(_) => {}
        }
        let listed = self.allow_functions.as_ref().map(|a| a.contains(&function));
        if self.read_only {
            // An allow-list: what is not known to be harmless is refused, unless explicitly allowed.
            if !read_only_safe(pdu) && listed != Some(true) {
                return Err(Refusal::ReadOnly);
            }
        } else if listed == Some(false) {
            return Err(Refusal::FunctionNotAllowed);
        }
        if let Some(bucket) = bucket
            && !bucket.take(now)
        {
            return Err(Refusal::RateLimit);
        }
        if target == 0 && !broadcastable(function) {
            // A broadcast read would make every device on the line answer at once (or none).
            return Err(Refusal::BroadcastNotWrite);
        }
        if target == 0 && !self.broadcast {
            return Err(Refusal::Broadcast);
        }
        let route = self.routes.iter().position(|r| r.contains(&target) || target == 0).ok_or(Refusal::NoRoute)?;
        let high = peer_high
            || self.priority.iter().any(|p| match p {
                Priority::Units(u) => u.contains(&target),
                Priority::Functions(f) => f.contains(&function),
                Priority::Net(_) => false,
            });
        Ok(Admitted { target, route, high })
    }

    /// Whether a request to `unit` has a line to go to (after `--map-unit`): a front on a serial
    /// line stands for those units only and stays silent for the others, as a slave answers
    /// its own address alone (Serial Line v1.02 §2.2). Broadcasts go everywhere.
    #[must_use]
    pub fn serves(&self, unit: u8) -> bool {
        let target = self.unit_map.get(&unit).copied().unwrap_or(unit);
        target == 0 || self.routes.iter().any(|r| r.contains(&target))
    }

    /// Whether a client at `ip` is in the priority class for all its requests.
    #[must_use]
    pub fn peer_high(&self, ip: IpAddr) -> bool {
        self.priority.iter().any(|p| matches!(p, Priority::Net(n) if n.contains(ip)))
    }
}

/// A token bucket: `rate` requests per second, bursts up to one second's worth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateLimit {
    rate: f64,
    tokens: f64,
    at: Duration,
}

impl RateLimit {
    /// Full at `now`.
    #[must_use]
    pub fn new(rate: f64, now: Duration) -> Self {
        let rate = rate.max(f64::MIN_POSITIVE);
        Self { rate, tokens: rate.max(1.0), at: now }
    }

    /// Takes a token at `now`, if one is there.
    pub fn take(&mut self, now: Duration) -> bool {
        let elapsed = now.saturating_sub(self.at).as_secs_f64();
        self.tokens = (self.tokens + elapsed * self.rate).min(self.rate.max(1.0));
        self.at = self.at.max(now);
        if self.tokens < 1.0 {
            return false;
        }
        self.tokens -= 1.0;
        true
    }
}

/// One `--priority high=…` rule: a client network, units or function codes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Priority {
    Net(IpNet),
    Units(BTreeSet<u8>),
    Functions(BTreeSet<u8>),
}

/// `high=ip:10.0.0.0/24`, `high=unit:1-5`, `high=fc:5,6,15,16`.
///
/// # Errors
/// What is wrong with the value.
pub fn parse_priority(spec: &str) -> Result<Priority, BadValue> {
    let bad = |why: String| {
        BadValue(format!("--priority {spec:?}: {why}; expected high=ip:NET, high=unit:UNITS or high=fc:CODES"))
    };
    let rule = spec.strip_prefix("high=").ok_or_else(|| bad("only the class \"high\" exists".into()))?;
    match rule.split_once(':') {
        Some(("ip", net)) => net.parse().map(Priority::Net).map_err(|e: BadValue| bad(e.0)),
        Some(("unit", units)) => parse_units(units).map(Priority::Units).map_err(|e| bad(e.0)),
        Some(("fc", codes)) => parse_function_codes(codes)
            .map(Priority::Functions)
            .ok_or_else(|| bad(format!("{codes:?} is not a list of function codes"))),
        _ => Err(bad(format!("{rule:?}"))),
    }
}

/// An address or a network (`192.168.1.0/24`, `::1`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IpNet {
    pub addr: IpAddr,
    pub prefix: u8,
}

impl std::str::FromStr for IpNet {
    type Err = BadValue;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || BadValue(format!("{s:?} is not an IP address or network like 192.168.1.0/24"));
        let (a, p) = s.split_once('/').map_or((s, None), |(a, p)| (a, Some(p)));
        let addr: IpAddr = a.trim().parse().map_err(|_| bad())?;
        let max = if addr.is_ipv4() { 32 } else { 128 };
        let prefix = match p {
            Some(p) => p.trim().parse::<u8>().ok().filter(|&p| p <= max).ok_or_else(bad)?,
            None => max,
        };
        // An IPv4-mapped IPv6 address (::ffff:10.0.0.5) is that IPv4 address: peers are compared
        // in their IPv4 form, so the net must be too, or it would match no one.
        if let IpAddr::V6(v6) = addr
            && let Some(v4) = v6.to_ipv4_mapped()
            && prefix >= 96
        {
            return Ok(Self { addr: IpAddr::V4(v4), prefix: prefix - 96 });
        }
        Ok(Self { addr, prefix })
    }
}

impl IpNet {
    #[must_use]
    pub fn contains(&self, ip: IpAddr) -> bool {
        match (self.addr, canonical(ip)) {
            (IpAddr::V4(net), IpAddr::V4(ip)) => {
                let mask = u32::MAX.checked_shl(32 - u32::from(self.prefix)).unwrap_or(0);
                u32::from(net) & mask == u32::from(ip) & mask
            }
            (IpAddr::V6(net), IpAddr::V6(ip)) => {
                let mask = u128::MAX.checked_shl(128 - u32::from(self.prefix)).unwrap_or(0);
                u128::from(net) & mask == u128::from(ip) & mask
            }
            _ => false,
        }
    }
}

/// A client's address as its budgets and rules know it: an IPv4-mapped IPv6 address
/// (`::ffff:10.0.0.5`, a dual-stack listener's view of an IPv4 client) is that IPv4 address.
#[must_use]
pub fn canonical(ip: IpAddr) -> IpAddr {
    match ip {
        IpAddr::V6(v6) => v6.to_ipv4_mapped().map_or(ip, IpAddr::V4),
        v4 @ IpAddr::V4(_) => v4,
    }
}

/// Whether a client at `ip` may connect: an empty allow-list lets everyone in — the listener's
/// own choice, said in its help — a non-empty one only its networks.
#[must_use]
pub fn ip_allowed(allow: &[IpNet], ip: IpAddr) -> bool {
    allow.is_empty() || allow.iter().any(|n| n.contains(ip))
}

/// What one TLS role may do (MODBUS/TCP Security: the role from the client certificate).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RoleRules {
    pub functions: Option<BTreeSet<u8>>,
    pub units: Option<BTreeSet<u8>>,
    pub read_only: bool,
}

impl RoleRules {
    /// Whether the role may send `pdu` to `unit`.
    #[must_use]
    pub fn allows(&self, unit: u8, pdu: &[u8]) -> bool {
        let function = pdu.first().copied().unwrap_or(0);
        self.functions.as_ref().is_none_or(|f| f.contains(&function))
            && self.units.as_ref().is_none_or(|u| u.contains(&unit))
            && (!self.read_only || read_only_safe(pdu))
    }
}

/// Roles by name.
pub type Roles = BTreeMap<String, RoleRules>;

/// `--role NAME=RULES` values (`viewer=read-only`, `ops=functions:3,6;units:1-10`, `admin=all`).
///
/// # Errors
/// Which value is wrong and why.
pub fn parse_roles(values: &[String]) -> Result<Roles, BadValue> {
    let mut out = Roles::new();
    for v in values {
        let bad = |why: String| BadValue(format!("--role {v:?}: {why}"));
        let (name, rules) =
            v.split_once('=').ok_or_else(|| bad("expected NAME=RULES, e.g. viewer=read-only".into()))?;
        let name = name.trim();
        if name.is_empty() {
            return Err(bad("the role has no name".into()));
        }
        let mut r = RoleRules::default();
        let mut any = false;
        for rule in rules.split(';').map(str::trim).filter(|r| !r.is_empty()) {
            any = true;
            match rule.split_once(':') {
                None if rule == "read-only" => r.read_only = true,
                // Everything, said on purpose: an empty rule set is never taken for it.
                None if rule == "all" => {}
                Some(("functions", list)) => {
                    let codes = parse_function_codes(list)
                        .ok_or_else(|| bad(format!("{list:?} is not a list of function codes")))?;
                    r.functions = Some(codes);
                }
                Some(("units", list)) => r.units = Some(parse_units(list).map_err(|e| bad(e.0))?),
                _ => return Err(bad(format!("{rule:?} is not functions:…, units:…, read-only or all"))),
            }
        }
        // Fail closed: `admin=` or an empty [roles.admin] let a client do everything.
        if !any {
            return Err(bad(format!(
                "role {name:?} has no rules; an empty rule set would allow everything — give functions:…, units:…, read-only, or `all` to allow everything on purpose"
            )));
        }
        if out.contains_key(name) {
            return Err(bad(format!(
                "role {name:?} is given twice; a second rule set would silently replace the first — merge them into one"
            )));
        }
        out.insert(name.to_owned(), r);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Read holding 0, one register (MAP v1.1b3 §6.3): function 03, address 0000, quantity 0001.
    const READ_ONE: [u8; 5] = [0x03, 0x00, 0x00, 0x00, 0x01];
    /// Write single register 1 = 3 (MAP v1.1b3 §6.6): function 06, address 0001, value 0003.
    const WRITE_ONE: [u8; 5] = [0x06, 0x00, 0x01, 0x00, 0x03];
    /// A read with one byte too many behind it (a smuggled frame).
    const READ_TOO_LONG: [u8; 6] = [0x03, 0x00, 0x00, 0x00, 0x01, 0x06];
    /// A vendor read, function 0x46 (user-defined, MAP v1.1b3 §5).
    const VENDOR: [u8; 3] = [0x46, 0x00, 0x00];

    fn policy() -> Policy {
        Policy { routes: vec![1..=10, 20..=30], ..Policy::default() }
    }

    fn ask(unit: u8, pdu: &[u8]) -> Asked<'_> {
        Asked { unit, pdu, role: Role::Plain, peer_high: false }
    }

    #[test]
    fn routes_map_units_and_the_unrouted_get_0a() {
        let mut p = policy();
        p.unit_map.insert(100, 25);
        assert_eq!(p.admit(ask(3, &READ_ONE), None, Duration::ZERO), Ok(Admitted { target: 3, route: 0, high: false }));
        assert_eq!(p.admit(ask(100, &READ_ONE), None, Duration::ZERO).map(|a| (a.target, a.route)), Ok((25, 1)));
        let refused = p.admit(ask(15, &READ_ONE), None, Duration::ZERO);
        assert_eq!(refused, Err(Refusal::NoRoute));
        assert_eq!(Refusal::NoRoute.exception().value(), 0x0A);
    }

    #[test]
    fn read_only_refuses_writes_and_unknown_codes_unless_listed() {
        let mut p = Policy { read_only: true, ..policy() };
        assert!(p.admit(ask(1, &READ_ONE), None, Duration::ZERO).is_ok());
        assert_eq!(p.admit(ask(1, &WRITE_ONE), None, Duration::ZERO), Err(Refusal::ReadOnly));
        assert_eq!(p.admit(ask(1, &VENDOR), None, Duration::ZERO), Err(Refusal::ReadOnly));
        p.allow_functions = Some(vec![0x46]);
        assert!(p.admit(ask(1, &VENDOR), None, Duration::ZERO).is_ok(), "listed on top of the read-only set");
        assert_eq!(p.admit(ask(1, &WRITE_ONE), None, Duration::ZERO), Err(Refusal::ReadOnly));
        // Without read-only, the list is the whole allow-list.
        p.read_only = false;
        assert_eq!(p.admit(ask(1, &READ_ONE), None, Duration::ZERO), Err(Refusal::FunctionNotAllowed));
        assert_eq!(Refusal::ReadOnly.exception().value(), 0x01);
    }

    #[test]
    fn a_request_of_the_wrong_length_is_refused_first() {
        let p = Policy { read_only: true, ..policy() };
        assert_eq!(p.admit(ask(1, &READ_TOO_LONG), None, Duration::ZERO), Err(Refusal::Malformed));
        assert_eq!(Refusal::Malformed.exception().value(), 0x03);
        assert_eq!(p.admit(ask(1, &[]), None, Duration::ZERO), Err(Refusal::Malformed));
    }

    #[test]
    fn roles_judge_the_serial_address_and_no_role_is_nothing() {
        let mut p = policy();
        p.unit_map.insert(10, 1);
        let roles = parse_roles(&["ops=units:2-20;functions:3".into(), "viewer=read-only".into()]).unwrap();
        let ops = Role::Tls(roles.get("ops"));
        let viewer = Role::Tls(roles.get("viewer"));
        let as_role = |unit, pdu, role| p.admit(Asked { unit, pdu, role, peer_high: false }, None, Duration::ZERO);
        assert!(as_role(5, &READ_ONE[..], ops).is_ok());
        assert_eq!(as_role(10, &READ_ONE[..], ops), Err(Refusal::Role), "unit 10 is mapped to 1, outside 2-20");
        assert_eq!(as_role(5, &WRITE_ONE[..], ops), Err(Refusal::Role));
        assert_eq!(as_role(5, &WRITE_ONE[..], viewer), Err(Refusal::Role));
        assert_eq!(as_role(5, &READ_ONE[..], Role::Tls(None)), Err(Refusal::NoRole));
    }

    #[test]
    fn roles_fail_closed_on_empty_or_repeated_rules() {
        for bad in [&["admin="][..], &["=all"], &["x=write"], &["a=all", "a=read-only"], &["a=functions:z"]] {
            let values: Vec<String> = bad.iter().map(|s| (*s).to_owned()).collect();
            let e = parse_roles(&values).unwrap_err();
            assert!(e.0.contains("--role"), "{e}");
        }
        let all = parse_roles(&["admin=all".into()]).unwrap();
        assert!(all["admin"].allows(7, &WRITE_ONE));
    }

    #[test]
    fn broadcasts_carry_writes_only() {
        let p = Policy { broadcast: true, ..policy() };
        assert_eq!(p.admit(ask(0, &READ_ONE), None, Duration::ZERO), Err(Refusal::BroadcastNotWrite));
        assert_eq!(p.admit(ask(0, &WRITE_ONE), None, Duration::ZERO).map(|a| a.target), Ok(0));
    }

    /// Unit 0 is refused from every front unless `--allow-broadcast`, the broker's writes included
    /// (never a broadcast reported `"ok": true`), and a unit mapped to 0 as well.
    #[test]
    fn broker_broadcast_writes_are_refused_unless_allowed() {
        let mut p = policy();
        let broker = Asked { unit: 0, pdu: &WRITE_ONE, role: Role::Broker(None), peer_high: false };
        assert_eq!(p.admit(broker, None, Duration::ZERO), Err(Refusal::Broadcast));
        assert_eq!(p.admit(ask(0, &WRITE_ONE), None, Duration::ZERO), Err(Refusal::Broadcast));
        p.unit_map.insert(5, 0);
        assert_eq!(p.admit(ask(5, &WRITE_ONE), None, Duration::ZERO), Err(Refusal::Broadcast));
        assert_eq!(Refusal::Broadcast.exception().value(), 0x01);
        p.broadcast = true;
        assert!(p.admit(broker, None, Duration::ZERO).is_ok());
        // The broker under a role: its rules judge.
        let roles = parse_roles(&["viewer=read-only".into()]).unwrap();
        let viewer = Asked { unit: 1, pdu: &WRITE_ONE, role: Role::Broker(roles.get("viewer")), peer_high: false };
        assert_eq!(p.admit(viewer, None, Duration::ZERO), Err(Refusal::Role));
    }

    /// Under `--read-only --allow-function 8`, an FC08/0000 with a CRC-valid write frame in its
    /// data never reaches the line, where a slave framing by structure would execute the write.
    #[test]
    fn an_fc08_longer_than_one_data_word_is_refused_under_every_policy() {
        /// Diagnostics 0000 Return Query Data, data 1234, then `01 06 00 65 00 2C` + CRC: a
        /// write of holding 101 = 44 to unit 1 hidden in the echo.
        const SMUGGLE: [u8; 13] = [0x08, 0x00, 0x00, 0x12, 0x34, 0x01, 0x06, 0x00, 0x65, 0x00, 0x2C, 0x98, 0x2C];
        const ECHO: [u8; 5] = [0x08, 0x00, 0x00, 0x12, 0x34];
        let open = policy();
        let allowed = Policy { read_only: true, allow_functions: Some(vec![0x08]), ..policy() };
        for p in [&open, &allowed] {
            assert_eq!(p.admit(ask(1, &SMUGGLE), None, Duration::ZERO), Err(Refusal::Malformed));
            assert!(p.admit(ask(1, &ECHO), None, Duration::ZERO).is_ok());
        }
    }

    #[test]
    fn the_rate_limit_refills_with_the_virtual_clock() {
        let p = policy();
        let mut bucket = RateLimit::new(2.0, Duration::ZERO);
        let mut at = |ms| p.admit(ask(1, &READ_ONE), Some(&mut bucket), Duration::from_millis(ms));
        assert!(at(0).is_ok());
        assert!(at(0).is_ok());
        assert_eq!(at(0), Err(Refusal::RateLimit), "a burst of one second's worth");
        assert_eq!(at(400), Err(Refusal::RateLimit), "0.8 tokens");
        assert!(at(500).is_ok(), "one token after half a second");
        assert_eq!(Refusal::RateLimit.exception().value(), 0x06);
    }

    #[test]
    fn priorities_by_peer_unit_and_function() {
        let mut p = policy();
        p.priority = vec![
            parse_priority("high=unit:5").unwrap(),
            parse_priority("high=fc:6").unwrap(),
            parse_priority("high=ip:10.0.0.0/24").unwrap(),
        ];
        let high = |unit, pdu| p.admit(ask(unit, pdu), None, Duration::ZERO).unwrap().high;
        assert!(high(5, &READ_ONE[..]));
        assert!(high(1, &WRITE_ONE[..]));
        assert!(!high(1, &READ_ONE[..]));
        assert!(p.peer_high("10.0.0.9".parse().unwrap()));
        assert!(!p.peer_high("10.0.1.9".parse().unwrap()));
        for bad in ["low=unit:1", "high=unit:0", "high=fc:x", "high=ip:300.1.1.1", "high=port:5"] {
            assert!(parse_priority(bad).unwrap_err().0.contains(bad), "{bad}");
        }
    }

    #[test]
    fn ip_networks_match_their_addresses() {
        let net: IpNet = "192.168.1.0/24".parse().unwrap();
        assert!(net.contains("192.168.1.77".parse().unwrap()));
        assert!(!net.contains("192.168.2.1".parse().unwrap()));
        assert!(net.contains("::ffff:192.168.1.5".parse().unwrap()), "IPv4-mapped IPv6 peers");
        let one: IpNet = "127.0.0.1".parse().unwrap();
        assert!(one.contains("127.0.0.1".parse().unwrap()));
        assert!(!one.contains("127.0.0.2".parse().unwrap()));
        let all: IpNet = "0.0.0.0/0".parse().unwrap();
        assert!(all.contains("10.1.2.3".parse().unwrap()));
        assert!("10.0.0.0/33".parse::<IpNet>().is_err());
        // A mapped address on the allow-list matched no client.
        let mapped: IpNet = "::ffff:127.0.0.1".parse().unwrap();
        assert!(mapped.contains("127.0.0.1".parse().unwrap()));
        assert!(mapped.contains("::ffff:127.0.0.1".parse().unwrap()));
        let mapped_net: IpNet = "::ffff:10.0.0.0/120".parse().unwrap();
        assert!(mapped_net.contains("10.0.0.77".parse().unwrap()));
        assert!(!mapped_net.contains("10.0.1.1".parse().unwrap()));
        assert!("nonsense".parse::<IpNet>().is_err());
        assert!(ip_allowed(&[], "10.0.0.1".parse().unwrap()));
        assert!(!ip_allowed(&[net], "10.0.0.1".parse().unwrap()));
    }
}
