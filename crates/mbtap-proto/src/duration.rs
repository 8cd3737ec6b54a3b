//! Durations as people type them on a command line or in a configuration file: `250ms`, `1s`,
//! `1.5` (seconds), `2min`, `1h`. One parser for every option that takes one (`watch
//! --interval`, `--max-age`, `--mqtt-interval`, the bridge's `--cache` and `--poll` ages).

use std::time::Duration;

/// Parses `s` and checks it lies in `min..=max`.
///
/// # Errors
/// What was typed and what is expected, ready to show.
pub fn parse_duration(s: &str, min: Duration, max: Duration) -> Result<Duration, String> {
    let t = s.trim();
    let (number, scale) = [("ms", 1e-3), ("min", 60.0), ("h", 3600.0), ("s", 1.0)]
        .iter()
        .find_map(|&(suffix, scale)| t.strip_suffix(suffix).map(|n| (n, scale)))
        .unwrap_or((t, 1.0));
    let secs = number
        .trim()
        .parse::<f64>()
        .ok()
        .map(|v| v * scale)
        .filter(|v| v.is_finite())
        .ok_or_else(|| format!("{s:?} is not a duration like 250ms, 1s, 2min or 1h"))?;
    if !(min.as_secs_f64()..=max.as_secs_f64()).contains(&secs) {
        return Err(format!("{s:?} is outside {min:?}..={max:?}"));
    }
    Ok(Duration::from_secs_f64(secs))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    const DAY: Duration = Duration::from_hours(24);

    #[test]
    fn the_units_people_write() {
        assert_eq!(parse_duration("250ms", Duration::ZERO, DAY), Ok(Duration::from_millis(250)));
        assert_eq!(parse_duration(" 1.5 ", Duration::ZERO, DAY), Ok(Duration::from_millis(1500)));
        assert_eq!(parse_duration("2min", Duration::ZERO, DAY), Ok(Duration::from_mins(2)));
        assert_eq!(parse_duration("1h", Duration::ZERO, DAY), Ok(Duration::from_hours(1)));
        assert!(parse_duration("0", Duration::from_millis(1), DAY).unwrap_err().contains("outside"));
        assert!(parse_duration("soon", Duration::ZERO, DAY).unwrap_err().contains("not a duration"));
        assert!(parse_duration("NaN", Duration::ZERO, DAY).is_err());
        assert!(parse_duration("-1s", Duration::ZERO, DAY).is_err());
    }
}
