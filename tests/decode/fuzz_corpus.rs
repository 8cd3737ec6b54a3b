//! Every fuzz seed and every saved crash input (`fuzz/seeds/*`, `fuzz/regressions/*`) through
//! the same harness bodies the fuzzers run, so `cargo test` keeps them green without cargo-fuzz.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::fs;
use std::path::Path;

fn run_dir(dir: &Path) -> usize {
    let Ok(targets) = fs::read_dir(dir) else { return 0 };
    let mut n = 0;
    for target in targets {
        let target = target.unwrap().path();
        let name = target.file_name().unwrap().to_string_lossy().into_owned();
        let body: fn(&[u8]) = match name.as_str() {
            "rtu" => mbtap_analysis::fuzzing::rtu,
            "ascii" => mbtap_analysis::fuzzing::ascii,
            "tcp" => mbtap_analysis::fuzzing::tcp_stream,
            "pdu_request" => mbtap_analysis::fuzzing::pdu_request,
            "pdu_response" => mbtap_analysis::fuzzing::pdu_response,
            "roundtrip" => mbtap_analysis::fuzzing::roundtrip,
            "decode_text" => mbtap_analysis::fuzzing::decode_text,
            "decode_lines" => mbtap_analysis::fuzzing::decode_lines,
            "framer" => mbtap_analysis::fuzzing::framer,
            "capture" => mbtap_analysis::fuzzing::capture,
            "profile" => mbtap_device::fuzzing::profile,
            "sim" => mbtap_sim::fuzzing::sim,
            "uart" => mbtap_sim::fuzzing::uart,
            "bridge_response" => mbtap_analysis::fuzzing::bridge_response,
            "health" => mbtap_analysis::fuzzing::health,
            "query" => mbtap_device::fuzzing::query,
            "learn" => mbtap_analysis::fuzzing::learn,
            "profile_import" => mbtap_device::fuzzing::profile_import,
            "ods_size" => mbtap_device::fuzzing::ods_size,
            "xls_rows" => mbtap_device::fuzzing::xls_rows,
            "xls_container" => mbtap_device::fuzzing::xls_container,
            "ods_rows" => mbtap_device::fuzzing::ods_rows,
            "sunspec" => mbtap_device::fuzzing::sunspec,
            "spool" => mbtap_publish::fuzzing::spool,
            "sparkplug" => mbtap_publish::fuzzing::sparkplug,
            "export_escape" => |d| {
                mbtap_device::fuzzing::export_escape(d);
            },
            "gateway" => mbtap_gateway::fuzzing::transaction,
            "gateway_transports" => mbtap_gateway::fuzzing::transports,
            "lifetime" => mbtap_gateway::fuzzing::lifetime,
            "import_file" => mbtap::cmd::profiles::fuzzing::import_file,
            other => panic!("{} names no fuzz target ({other})", target.display()),
        };
        for file in fs::read_dir(&target).unwrap() {
            body(&fs::read(file.unwrap().path()).unwrap());
            n += 1;
        }
    }
    n
}

#[test]
fn seeds_and_regressions_pass_every_harness() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz");
    let seeds = run_dir(&root.join("seeds"));
    run_dir(&root.join("regressions"));
    assert!(seeds >= 7, "fuzz seeds missing: ran {seeds}");
}
