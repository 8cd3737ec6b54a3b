//! The HTML health report in a real browser: headless Chromium opens the self-contained page
//! and lays out its three plots (the page marks how many plots have a size and marks in them).
//! Needs chromium: `#[ignore]`d in a plain `cargo test`, run by `.ci/run` with `--ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::process::Command;

#[test]
#[ignore = "needs chromium; .ci/run installs it and runs this with --ignored"]
fn the_html_report_opens_in_a_browser_with_its_plots() {
    let capture = concat!(env!("CARGO_MANIFEST_DIR"), "/captures/rtu-19200-8e1-usb1ms-noisy.pcapng");
    let out = Command::new(env!("CARGO_BIN_EXE_mbtap")).args(["report", capture, "--format", "html"]).output().unwrap();
    assert!(out.status.success());
    let dir = std::env::temp_dir().join(format!("mbtap-report-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let page = dir.join("report.html");
    std::fs::write(&page, &out.stdout).unwrap();
    let browser = ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|b| Command::new(b).arg("--version").output().is_ok_and(|o| o.status.success()))
        .expect("chromium must be installed for this test");
    let dom = Command::new(browser)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--dump-dom"])
        .arg(format!("file://{}", page.display()))
        .output()
        .unwrap();
    let dom = String::from_utf8_lossy(&dom.stdout);
    assert!(
        dom.contains("data-plots=\"3\""),
        "the browser did not lay out the three plots:\n{}",
        &dom[..dom.len().min(2000)]
    );
    assert!(dom.contains("data-kind=\"check_errors\""), "the findings are on the page");
}
