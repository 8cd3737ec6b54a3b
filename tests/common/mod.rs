//! Helpers shared by the tests that drive the real binary on pseudo-terminals.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::process::Child;
use std::time::{Duration, Instant};

/// The binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_mbtap");

/// A child process killed and reaped when the test ends, pass or fail.
pub struct Kill(pub Child);

impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Waits (up to 10 s) for a path to appear: a pty link, a recording.
pub fn wait_for(path: &std::path::Path) {
    let start = Instant::now();
    while !path.exists() {
        assert!(start.elapsed() < Duration::from_secs(10), "{} never appeared", path.display());
        std::thread::sleep(Duration::from_millis(20));
    }
}
