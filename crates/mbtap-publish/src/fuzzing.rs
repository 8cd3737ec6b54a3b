//! Fuzz harness bodies of publishing (the spool, Sparkplug): kept in the library so the
//! `fuzz/` targets stay one-liners and the same bodies run over the seed corpus in `cargo test`
//! (tests/decode/fuzz_corpus.rs).
//!
//! Each function must not panic on any input; a body that asserts a property says so in its
//! `# Panics` — there a panic is the finding.

/// Any bytes as a store-and-forward buffer file (torn, damaged, someone else's), every record
/// read back as the publisher forwards it; and as one record's body, written and read again.
///
/// # Panics
/// When a record written does not read back as written: the point of this harness.
pub fn spool(data: &[u8]) {
    let parsed = crate::spool::parse_records(data);
    for (kind, body) in &parsed.records {
        if *kind == crate::spool::Kind::Mqtt {
            let _ = crate::spool::parse_mqtt_body(body);
        }
    }
    let mut file = Vec::new();
    if crate::spool::encode_record(crate::spool::Kind::Sparkplug, data, &mut file) {
        let again = crate::spool::parse_records(&file);
        assert_eq!(again.records, [(crate::spool::Kind::Sparkplug, data)], "a record reads back as written");
    }
}

/// Any bytes as a Sparkplug payload from the broker (an NCMD to the node), as a held update
/// read back from the buffer, and as a value the node publishes.
pub fn sparkplug(data: &[u8]) {
    use crate::sparkplug::{EdgeNode, Sample};
    let _ = crate::sparkplug::Payload::parse_payload(data);
    let mut node = EdgeNode::new("g", "n", 1);
    let _ = node.will();
    node.online(0);
    let _ = node.command("spBv1.0/g/NCMD/n", data, 1);
    let _ = node.historical(data, 2);
    let text = String::from_utf8_lossy(data);
    let value = serde_json::from_str(&text).unwrap_or(serde_json::Value::String(text.clone().into_owned()));
    let sample = Sample {
        name: crate::sparkplug::node::metric_name(&text),
        value,
        bits: data.first().is_some_and(|b| b & 1 == 1),
        unit: Some(text.into_owned()),
        t_ms: 3,
    };
    let _ = node.update(&String::from_utf8_lossy(data), vec![sample], 5, 3);
    let _ = node.tick(u64::MAX, 4);
    node.offline();
}
