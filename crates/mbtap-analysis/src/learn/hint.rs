//! `learn --hint UNIT:TABLE:ADDRESS=VALUE`: a value the user read off the device's display when
//! the capture ended. Against the register's last raw value it fixes the scale (a power of ten
//! when one is within 2 %, the plain ratio otherwise, said as such), or confirms a float.

use mbtap_device::profile::Table;

/// One hint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hint {
    pub unit: u8,
    pub table: Table,
    pub address: u16,
    pub value: f64,
}

/// `1:holding:105=1.5`, `7:input:30001=230.4` (a table word as `read` takes it).
///
/// # Errors
/// Which part is wrong, with the value and an example.
pub fn parse_hint(s: &str) -> Result<Hint, String> {
    let bad = |why: &str| format!("--hint {s:?}: {why}; expected UNIT:TABLE:ADDRESS=VALUE, e.g. 1:holding:105=1.5");
    let (place, value) = s.split_once('=').ok_or_else(|| bad("no =VALUE"))?;
    let mut parts = place.split(':');
    let (Some(unit), Some(table), Some(address), None) = (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return Err(bad("UNIT:TABLE:ADDRESS has three parts"));
    };
    let unit = unit.trim().parse::<u8>().map_err(|_| bad(&format!("{unit:?} is not a unit 0–255")))?;
    let table = mbtap_device::query::table_word(table.trim())
        .ok_or_else(|| bad(&format!("{table:?} is not coils, discrete, holding or input")))?;
    let address = address.trim().parse::<u16>().map_err(|_| bad(&format!("{address:?} is not an address 0–65535")))?;
    let value = value
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| bad(&format!("{value:?} is not a number")))?;
    Ok(Hint { unit, table, address, value })
}

/// What a hint says of a register whose last raw value (as its guessed type reads it) was
/// `raw`: the scale to write, if any, and the sentence for the draft's comment.
#[must_use]
pub fn scale_from(hint: f64, raw: f64, is_float: bool) -> (Option<f64>, String) {
    let close = |a: f64, b: f64| (a - b).abs() <= 0.02 * b.abs().max(1e-12);
    if is_float && close(raw, hint) {
        return (None, format!("the device showed {hint} when the float read {raw}: confirmed, no scale"));
    }
    if raw == 0.0 {
        return (None, format!("the device showed {hint} when the register read 0: no scale can be told"));
    }
    let ratio = hint / raw;
    if let Some(k) = (-6..=6).find(|&k| close(ratio, 10f64.powi(k))) {
        let scale = 10f64.powi(k);
        return (Some(scale), format!("the device showed {hint} when the register read {raw}: scale {scale}"));
    }
    // Six significant digits: enough for any display, and no float noise in the profile.
    // The exponent of a finite, non-zero ratio of finite values: within ±330, clamped anyway.
    #[allow(clippy::cast_possible_truncation)]
    let magnitude = ratio.abs().log10().floor().clamp(-300.0, 300.0) as i32;
    let p = 10f64.powi((5 - magnitude).clamp(-12, 12));
    let scale = (ratio * p).round() / p;
    (
        Some(scale),
        format!("the device showed {hint} when the register read {raw}: scale {scale} (not a power of ten: check it)"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hints_parse_or_say_what_is_wrong() {
        let h = parse_hint("1:holding:105=1.5").unwrap();
        assert_eq!((h.unit, h.table, h.address, h.value), (1, Table::HoldingRegisters, 105, 1.5));
        for bad in
            ["1:holding:105", "1:holding=1", "x:holding:1=1", "1:registers:1=1", "1:holding:1=abc", "1:holding:1=inf"]
        {
            assert!(parse_hint(bad).unwrap_err().contains("--hint"), "{bad}");
        }
    }

    #[test]
    fn the_scale_is_a_power_of_ten_when_one_fits() {
        assert_eq!(scale_from(230.4, 2304.0, false).0, Some(0.1));
        assert_eq!(scale_from(1.5, 150.0, false).0, Some(0.01));
        assert_eq!(scale_from(230.4, 230.41, true).0, None, "a float that reads as shown");
        let (s, said) = scale_from(50.0, 3.0, false);
        assert!(s.is_some_and(|s| (s - 16.6667).abs() < 1e-3) && said.contains("not a power of ten"), "{said}");
        assert_eq!(scale_from(5.0, 0.0, false).0, None);
    }
}
