//! The real binary's terminal UI in a real terminal: `mbtap demo` in a tmux pane, driven by
//! keys, its screen captured and checked for what a user would see — the three devices, a
//! filtered view, the help overlay — and `q` quitting with the terminal back in cooked mode.
//! Needs tmux: `#[ignore]`d in a plain `cargo test`, run by `.ci/run` with `--ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::process::Command;
use std::time::{Duration, Instant};

use crate::common;
use common::BIN;

/// A tmux server of its own (socket per test), killed at the end.
struct Tmux {
    socket: String,
}

impl Tmux {
    fn start(name: &str, command: &str, width: u16, height: u16) -> Self {
        let socket = format!("mbtap-{name}-{}", std::process::id());
        let t = Self { socket };
        let ok = t
            .cmd(&["new-session", "-d", "-s", "ui", "-x", &width.to_string(), "-y", &height.to_string(), command])
            .status
            .success();
        assert!(ok, "tmux must be installed for this test");
        t
    }

    fn cmd(&self, args: &[&str]) -> std::process::Output {
        Command::new("tmux").arg("-L").arg(&self.socket).args(args).output().expect("tmux must be installed")
    }

    fn keys(&self, keys: &[&str]) {
        let mut args = vec!["send-keys", "-t", "ui"];
        args.extend_from_slice(keys);
        assert!(self.cmd(&args).status.success());
    }

    fn screen(&self) -> String {
        String::from_utf8(self.cmd(&["capture-pane", "-p", "-t", "ui"]).stdout).unwrap()
    }

    /// Waits (up to 15 s) until the screen shows everything in `wanted`; the screen.
    fn wait_for(&self, wanted: &[&str]) -> String {
        let start = Instant::now();
        loop {
            let s = self.screen();
            if wanted.iter().all(|w| s.contains(w)) {
                return s;
            }
            assert!(start.elapsed() < Duration::from_secs(15), "never saw {wanted:?}; the screen:\n{s}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        let _ = self.cmd(&["kill-server"]);
    }
}

#[test]
#[ignore = "needs tmux; .ci/run installs it and runs this with --ignored"]
fn demo_in_a_real_terminal_shows_filters_helps_and_quits_cleanly() {
    // After mbtap exits the shell reports its status and the terminal mode.
    let command = format!("{BIN} demo; echo \"EXIT=$?\"; stty -a; echo MODES_DONE; sleep 60");
    let tmux = Tmux::start("demo", &command, 100, 30);

    // Live traffic from all three devices, annotated.
    let s = tmux.wait_for(&["Traffic", "mk4", "display", "mkzp", "Phase A (L1) voltage"]);
    assert!(s.contains("demo (simulated bus)"), "{s}");

    // Devices view: every unit with its counters.
    tmux.keys(&["2"]);
    tmux.wait_for(&["devices", "p50", "  1  mk4", "  5  display", " 17  mkzp"]);

    // Back to traffic, filtered to unit 5: only the Display's rows stay.
    tmux.keys(&["1", "u", "u"]);
    let s = tmux.wait_for(&["filter: unit 5"]);
    let rows: Vec<&str> = s.lines().filter(|l| l.contains(" ok ")).collect();
    assert!(!rows.is_empty(), "{s}");
    assert!(rows.iter().all(|l| l.contains("display")), "{s}");

    // The help overlay lists the keys.
    tmux.keys(&["?"]);
    tmux.wait_for(&["keys (any key closes)", "export the filtered rows", "quit"]);

    // q quits: exit status 0 and the terminal back in cooked mode with echo. MODES_DONE is
    // waited for because `stty -a` prints line by line: seeing "speed" alone raced it.
    tmux.keys(&["Escape"]);
    tmux.keys(&["q"]);
    let s = tmux.wait_for(&["EXIT=0", "speed", "MODES_DONE"]);
    let modes: Vec<&str> = s.split_whitespace().collect();
    assert!(modes.contains(&"icanon") && modes.contains(&"echo"), "terminal left in raw mode:\n{s}");
    assert!(!s.contains("devices"), "the alternate screen is gone:\n{s}");
}

#[test]
#[ignore = "needs tmux; .ci/run installs it and runs this with --ignored"]
fn sigterm_closes_the_ui_and_restores_the_terminal() {
    let pidfile = std::env::temp_dir().join(format!("mbtap-tui-pid-{}", std::process::id()));
    let pid_path = pidfile.display();
    let command =
        format!("sh -c 'echo $$ > {pid_path}; exec {BIN} demo'; echo \"EXIT=$?\"; stty -a; echo MODES_DONE; sleep 60");
    let tmux = Tmux::start("term", &command, 100, 30);
    tmux.wait_for(&["Traffic", "mk4"]);
    let pid = std::fs::read_to_string(&pidfile).unwrap();
    assert!(Command::new("kill").args(["-TERM", pid.trim()]).status().unwrap().success());
    let s = tmux.wait_for(&["EXIT=0", "speed", "MODES_DONE"]);
    let modes: Vec<&str> = s.split_whitespace().collect();
    assert!(modes.contains(&"icanon") && modes.contains(&"echo"), "terminal left in raw mode:\n{s}");
    let _ = std::fs::remove_file(&pidfile);
}
