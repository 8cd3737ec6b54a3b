//! Numeric option values, checked once where clap reads them: finite and inside the range the
//! option can mean, or refused naming that range. Nothing downstream sees `inf`, `NaN`, a
//! negative wait or a value that overflows a [`std::time::Duration`].

use std::ops::RangeInclusive;

/// A finite number within `range`; the error names the value and the range.
fn within(s: &str, range: &RangeInclusive<f64>, what: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("{s:?}: expected a number ({what})"))?;
    if v.is_finite() && range.contains(&v) {
        Ok(v)
    } else {
        Err(format!("{s}: expected {what}, from {} to {}", range.start(), range.end()))
    }
}

/// Milliseconds of a wait: 0 to one hour.
///
/// # Errors
/// Not a number, not finite, or outside 0–3 600 000.
pub fn millis(s: &str) -> Result<f64, String> {
    within(s, &(0.0..=3_600_000.0), "milliseconds")
}

/// Seconds of a wait or a period: above 0, up to 100 days.
///
/// # Errors
/// Not a number, not finite, 0 or less, or over 8 640 000.
pub fn seconds(s: &str) -> Result<f64, String> {
    let v = within(s, &(0.0..=8_640_000.0), "seconds")?;
    if v > 0.0 { Ok(v) } else { Err(format!("{s}: expected seconds above 0")) }
}

/// A rate per second: above 0, at most a million.
///
/// # Errors
/// Not a number, not finite, 0 or less, or over 1 000 000.
pub fn rate(s: &str) -> Result<f64, String> {
    let v = within(s, &(0.0..=1_000_000.0), "a rate per second")?;
    if v > 0.0 { Ok(v) } else { Err(format!("{s}: expected a rate above 0 per second")) }
}

/// A speed factor: 0 (as fast as it goes) or 0.001 to 1 000 000.
///
/// # Errors
/// Not a number, not finite, between 0 and 0.001, negative, or over 1 000 000.
pub fn speed(s: &str) -> Result<f64, String> {
    let v = within(s, &(0.0..=1_000_000.0), "a speed factor (0: as fast as it goes)")?;
    if v == 0.0 || v >= 0.001 {
        Ok(v)
    } else {
        Err(format!("{s}: expected 0 (as fast as it goes) or a speed factor from 0.001 to 1000000"))
    }
}

/// A probability: 0 to 1.
///
/// # Errors
/// Not a number, not finite, or outside 0–1.
pub fn probability(s: &str) -> Result<f64, String> {
    within(s, &(0.0..=1.0), "a probability")
}

/// An address or a network (`--allow-ip`, `--tls-allow-ip`): `10.0.0.5`, `10.0.0.0/24`, `::1`.
///
/// # Errors
/// The value, and what is expected.
pub fn ip_net(s: &str) -> Result<mbtap_gateway::admit::IpNet, String> {
    s.parse().map_err(|e: mbtap_gateway::BadValue| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_that_are_not_finite_or_out_of_range_are_refused_naming_the_range() {
        for bad in ["inf", "-inf", "nan", "NaN", "1e300", "-1", "x", ""] {
            assert!(millis(bad).is_err(), "{bad}");
            assert!(seconds(bad).is_err(), "{bad}");
            assert!(rate(bad).is_err(), "{bad}");
            assert!(speed(bad).is_err(), "{bad}");
            assert!(probability(bad).is_err(), "{bad}");
        }
        assert!(speed("1e-300").is_err());
        assert!(seconds("0").is_err());
        assert!(rate("0").is_err());
        let e = millis("1e300").unwrap_err();
        assert!(e.contains("0 to 3600000"), "{e}");
    }

    #[test]
    fn values_in_range_pass_unchanged() {
        assert_eq!(millis("0"), Ok(0.0));
        assert_eq!(millis("2.5"), Ok(2.5));
        assert_eq!(millis("1e-300"), Ok(1e-300));
        assert_eq!(seconds("0.5"), Ok(0.5));
        assert_eq!(rate("20"), Ok(20.0));
        assert_eq!(speed("0"), Ok(0.0));
        assert_eq!(speed("10"), Ok(10.0));
        assert_eq!(probability("0.02"), Ok(0.02));
    }
}
