//! Reads a capture with pcap-file or with mbtap-analysis' reader and prints what each got:
//! packets, payload bytes, and how it ended (the first error, or the warnings counted).
//!
//!     cargo run --release -- pcap-file FILE.pcapng
//!     cargo run --release -- mbtap FILE.pcapng

use std::fs::File;
use std::io::BufReader;

fn main() {
    let mut args = std::env::args().skip(1);
    let (Some(which), Some(path)) = (args.next(), args.next()) else {
        eprintln!("usage: pcap-file-eval pcap-file|mbtap FILE");
        std::process::exit(2);
    };
    let file = BufReader::with_capacity(1 << 20, File::open(&path).unwrap_or_else(|e| panic!("{path}: {e}")));
    let (mut packets, mut bytes, mut ended) = (0u64, 0u64, String::from("end of file"));
    if which == "pcap-file" {
        match pcap_file::pcapng::PcapNgReader::new(file) {
            Err(e) => ended = format!("error at start: {e}"),
            Ok(mut r) => {
                while let Some(block) = r.next_block() {
                    match block {
                        Ok((pcap_file::pcapng::Block::EnhancedPacket(p), _)) => {
                            packets += 1;
                            bytes += p.data.len() as u64;
                        }
                        Ok(_) => {}
                        Err(e) => {
                            ended = format!("stopped: {e}");
                            break;
                        }
                    }
                }
            }
        }
    } else {
        let mut r = mbtap_analysis::capture::CaptureReader::new(file);
        let mut warnings = 0u64;
        loop {
            match r.next_item() {
                Ok(Some(mbtap_analysis::capture::Item::Packet { data, .. })) => {
                    packets += 1;
                    bytes += data.len() as u64;
                }
                Ok(Some(mbtap_analysis::capture::Item::Warning(_))) => warnings += 1,
                Ok(Some(_)) => {}
                Ok(None) => break,
                Err(e) => {
                    ended = format!("stopped: {e}");
                    break;
                }
            }
        }
        ended = format!("{ended}, {warnings} warnings");
    }
    println!("{which}: {packets} packets, {bytes} bytes; {ended}");
}
