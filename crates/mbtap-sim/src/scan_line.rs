//! Line-settings detection on a simulated line: the frames as sent, heard through the UART
//! model at every candidate's settings and scored by the analysis' own scan
//! (`mbtap_analysis::scan`), so a scan test needs no port.

use mbtap_analysis::framer::LineSettings;
use mbtap_analysis::scan::{Score, candidates, rank, score};

/// Scans a simulated line: `frames` as sent at `sender` settings, heard through the UART model
/// at every candidate's settings. Ranked, best first.
#[must_use]
pub fn scan_line(frames: &[crate::bus::LineFrame], sender: LineSettings) -> Vec<Score> {
    let mut scores: Vec<Score> = candidates()
        .into_iter()
        .map(|c| {
            let mut uart = crate::uart::Listener::new(sender, c.line);
            let heard: Vec<(u64, Vec<u8>)> = frames
                .iter()
                .filter_map(|f| {
                    let bytes = uart.hear(f);
                    let t = bytes.last()?.0;
                    Some((t, bytes.into_iter().map(|(_, b)| b).collect()))
                })
                .collect();
            score(c, &heard)
        })
        .collect();
    rank(&mut scores);
    scores
}
