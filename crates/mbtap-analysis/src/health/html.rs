//! The health report as one self-contained HTML page a customer can open with no tools:
//! the findings with their evidence, per-unit figures, and three plots drawn as inline SVG —
//! latency over time, errors over time, availability per unit. No external files; one line of
//! script only marks, for automated checks, how many plots the browser laid out
//! (`<body data-plots="3">`).

use std::fmt::Write as _;

use crate::health::{Report, UnitHealth, clock};

const WIDTH: f64 = 760.0;
const HEIGHT: f64 = 180.0;
const MARGIN: f64 = 40.0;
/// Colours for units, in turn.
const PALETTE: [&str; 8] = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2"];

/// `2026-12-02` (UTC) of a time in ns since the Unix epoch (civil date from days: the
/// proleptic Gregorian calendar).
fn date(t_ns: u64) -> String {
    let (year, month, day) = crate::report::format::civil_date(i64::try_from(t_ns / 86_400_000_000_000).unwrap_or(0));
    format!("{year:04}-{month:02}-{day:02}")
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

#[allow(clippy::cast_precision_loss)]
fn f(v: u64) -> f64 {
    v as f64
}

/// The page.
#[must_use]
pub fn render(report: &Report, title: &str) -> String {
    let mut s = String::new();
    let _ = write!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>mbtap bus report — {t}</title>\n\
         <style>body{{font:14px system-ui,sans-serif;margin:2em;color:#222}}table{{border-collapse:collapse}}\
         td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}}th{{background:#eee}}td.l{{text-align:left}}\
         .finding{{margin:.5em 0;padding:.4em .8em;border-left:4px solid #d62728;background:#fdf3f3}}\
         .warning{{border-left-color:#e6a100;background:#fdf8ec}}.info{{border-left-color:#1f77b4;background:#f1f6fb}}\
         .ok{{border-left-color:#2ca02c;background:#f3fdf3}}td.alarm{{background:#fdf3f3}}td.warning{{background:#fdf8ec}}svg{{background:#fafafa;border:1px solid #ddd}}\
         .kind{{font-family:monospace;font-weight:bold}}</style></head><body>\n<h1>Bus report: {t}</h1>\n",
        t = esc(title)
    );
    // The date as well as the time (a page handed to a customer said neither date
    // nor line settings).
    let span = match (report.first_t_ns, report.last_t_ns) {
        (Some(a), Some(b)) => format!("{} {} to {} ({:.1} s)", date(a), clock(a), clock(b), f(b - a) / 1e9),
        _ => "no traffic".into(),
    };
    if let Some(line) = &report.line {
        let _ = writeln!(s, "<p>Line: {}</p>", esc(line));
    }
    for o in &report.observers {
        let _ = writeln!(s, "<p><small>{}</small></p>", esc(o.trim()));
    }
    let _ = write!(
        s,
        "<p>{span}: {} frames ({} failed checks, {} of them with no answer awaited), {} transactions, {} noise bursts ({} bytes).</p>\n<h2>Findings</h2>\n",
        report.frames,
        report.bad_frames,
        report.stray_frames,
        report.transactions,
        report.noise_bursts,
        report.noise_bytes
    );
    if report.findings.is_empty() {
        s.push_str("<div class=\"finding ok\">None — the bus looks healthy.</div>\n");
    }
    for fi in &report.findings {
        let who = fi.unit.map_or_else(|| "bus".to_owned(), |u| format!("unit {u}"));
        let times: Vec<String> = fi.evidence.iter().map(|&t| clock(t)).collect();
        let _ = writeln!(
            s,
            "<div class=\"finding {sev}\" data-kind=\"{k}\" data-severity=\"{sev}\"><span class=\"kind\">{k}</span> — {who}: {} \
             <br><small>{}×, from {} to {}; first at {}</small></div>",
            esc(&fi.summary),
            fi.count,
            clock(fi.first_t_ns),
            clock(fi.last_t_ns),
            times.join(", "),
            k = fi.kind,
            sev = crate::health::severity(fi)
        );
    }
    s.push_str("<h2>Units</h2>\n<table><tr><th>unit</th>");
    for (label, _) in report.units.first().map(UnitHealth::figures).unwrap_or_default() {
        let _ = write!(s, "<th>{}</th>", esc(label));
    }
    s.push_str("</tr>\n");
    for u in &report.units {
        let _ = write!(s, "<tr><td>{}</td>", u.unit);
        for (label, value) in u.figures() {
            // Availability coloured by what it means: ≥ 99 % plain, ≥ 90 % a warning, below an
            // alarm — not every figure in alarm red.
            let class = match (label, value.trim_end_matches(" %").parse::<f64>()) {
                ("availability", Ok(a)) if a < 90.0 => " class=\"alarm\"",
                ("availability", Ok(a)) if a < 99.0 => " class=\"warning\"",
                _ => "",
            };
            let _ = write!(s, "<td{class}>{}</td>", esc(&value));
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</table>\n<h2>Latency over time</h2>\n");
    s.push_str(&latency_plot(report));
    s.push_str("<h2>Errors over time</h2>\n<p><small>Unanswered requests, failed checks and noise bursts per slice of time.</small></p>\n");
    s.push_str(&errors_plot(report));
    s.push_str("<h2>Availability per unit</h2>\n");
    s.push_str(&availability_plot(report));
    s.push_str("<p><small>Made by mbtap report.</small></p>\n<script>document.body.dataset.plots=[...document.querySelectorAll('svg.plot')].filter(p=>p.getBBox().width>0&&p.querySelectorAll('circle,rect').length>0).length</script>\n</body></html>\n");
    s
}

fn axes(s: &mut String, id: &str, y_label: &str, y_max: &str) {
    let _ = write!(
        s,
        "<svg id=\"{id}\" class=\"plot\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\" xmlns=\"http://www.w3.org/2000/svg\">\
         <line x1=\"{m}\" y1=\"{b}\" x2=\"{r}\" y2=\"{b}\" stroke=\"#888\"/><line x1=\"{m}\" y1=\"10\" x2=\"{m}\" y2=\"{b}\" stroke=\"#888\"/>\
         <text x=\"4\" y=\"18\" font-size=\"11\">{y_max}</text><text x=\"4\" y=\"{b}\" font-size=\"11\">0</text>\
         <text x=\"{m}\" y=\"{hb}\" font-size=\"11\">{y_label}</text>",
        w = WIDTH,
        h = HEIGHT + 20.0,
        m = MARGIN,
        b = HEIGHT,
        r = WIDTH - 10.0,
        hb = HEIGHT + 16.0,
    );
}

fn latency_plot(report: &Report) -> String {
    let mut s = String::new();
    let max = report.latencies.iter().map(|p| p.latency_ns).max().unwrap_or(0).max(1);
    axes(&mut s, "latency", "latency of each answer, per unit (colour)", &format!("{:.1} ms", f(max) / 1e6));
    let (Some(first), Some(last)) = (report.first_t_ns, report.last_t_ns) else {
        s.push_str("</svg>\n");
        return s;
    };
    let span = f(last.saturating_sub(first)).max(1.0);
    let units: Vec<u8> = report.units.iter().map(|u| u.unit).collect();
    for p in &report.latencies {
        let x = MARGIN + f(p.t_ns.saturating_sub(first)) / span * (WIDTH - MARGIN - 10.0);
        let y = HEIGHT - f(p.latency_ns) / f(max) * (HEIGHT - 20.0);
        let colour = PALETTE[units.iter().position(|&u| u == p.unit).unwrap_or(0) % PALETTE.len()];
        let _ = write!(s, "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"1.6\" fill=\"{colour}\"/>");
    }
    for (i, u) in units.iter().enumerate() {
        let _ = write!(
            s,
            "<text x=\"{:.0}\" y=\"20\" font-size=\"11\" fill=\"{}\">unit {u}</text>",
            WIDTH - 70.0 * f(u64::try_from(units.len() - i).unwrap_or(1)),
            PALETTE[i % PALETTE.len()]
        );
    }
    s.push_str("</svg>\n");
    s
}

fn errors_plot(report: &Report) -> String {
    let mut s = String::new();
    let max = report.timeline.iter().map(|b| b.errors).max().unwrap_or(0).max(1);
    axes(&mut s, "errors", "errors per slice of time", &max.to_string());
    let n = f(u64::try_from(report.timeline.len()).unwrap_or(1)).max(1.0);
    let bar = (WIDTH - MARGIN - 10.0) / n;
    for (i, b) in report.timeline.iter().enumerate() {
        if b.errors == 0 {
            continue;
        }
        let h = f(b.errors) / f(max) * (HEIGHT - 20.0);
        let x = MARGIN + bar * f(u64::try_from(i).unwrap_or(0));
        let _ = write!(
            s,
            "<rect x=\"{x:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{h:.1}\" fill=\"#d62728\"><title>{} at {}</title></rect>",
            HEIGHT - h,
            (bar - 1.0).max(1.0),
            b.errors,
            clock(b.t_start_ns)
        );
    }
    s.push_str("</svg>\n");
    s
}

fn availability_plot(report: &Report) -> String {
    let mut s = String::new();
    axes(&mut s, "availability", "answered share of requests", "100 %");
    let n = f(u64::try_from(report.units.len()).unwrap_or(1)).max(1.0);
    let slot = (WIDTH - MARGIN - 10.0) / n;
    for (i, u) in report.units.iter().enumerate() {
        let h = u.availability_percent / 100.0 * (HEIGHT - 20.0);
        let x = MARGIN + slot * f(u64::try_from(i).unwrap_or(0)) + slot * 0.2;
        let colour = if u.availability_percent >= 99.9 { "#2ca02c" } else { "#d62728" };
        let _ = write!(
            s,
            "<rect x=\"{x:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{h:.1}\" fill=\"{colour}\"/>\
             <text x=\"{x:.1}\" y=\"{:.1}\" font-size=\"11\">unit {} {:.1} %</text>",
            HEIGHT - h,
            slot * 0.6,
            HEIGHT - h - 3.0,
            u.unit,
            u.availability_percent
        );
    }
    s.push_str("</svg>\n");
    s
}
