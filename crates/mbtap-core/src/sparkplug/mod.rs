//! Sparkplug B 3.0 (Eclipse Sparkplug Specification v3.0.0): the protobuf payload
//! ([`payload`]) and the edge node's state machine ([`node`]). Pure: the MQTT client, the
//! clock and the on-disk buffer are the binary's.

pub mod node;
pub mod payload;

pub use node::{EdgeNode, Emit, Held, Out, Sample};
pub use payload::{DataType, Metric, Payload, Value};
