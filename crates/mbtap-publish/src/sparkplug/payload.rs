//! The Sparkplug B payload (Sparkplug 3.0 §6.4, the `sparkplug_b.proto` of the specification,
//! `package org.eclipse.tahu.protobuf`): the part mbtap writes and reads, as prost messages with
//! the specification's field numbers. Fields mbtap never sets (templates, data sets, metadata,
//! extensions) are left out: protobuf skips unknown fields, so a payload with them still
//! decodes, and every payload written here decodes with the full `.proto` (checked in CI with
//! the `pysparkplug` package's compiled copy of it).

use prost::Message as _;

/// `Payload` (§6.4.1).
#[derive(Clone, PartialEq, prost::Message)]
pub struct Payload {
    /// Milliseconds since the epoch (UTC) when the message was sent.
    #[prost(uint64, optional, tag = "1")]
    pub timestamp: Option<u64>,
    #[prost(message, repeated, tag = "2")]
    pub metrics: Vec<Metric>,
    /// 0–255, one more per message of the session (§6.4.1; absent on NDEATH).
    #[prost(uint64, optional, tag = "3")]
    pub seq: Option<u64>,
    #[prost(string, optional, tag = "4")]
    pub uuid: Option<String>,
    #[prost(bytes = "vec", optional, tag = "5")]
    pub body: Option<Vec<u8>>,
}

/// `Payload.Metric` (§6.4.4).
#[derive(Clone, PartialEq, prost::Message)]
pub struct Metric {
    #[prost(string, optional, tag = "1")]
    pub name: Option<String>,
    #[prost(uint64, optional, tag = "2")]
    pub alias: Option<u64>,
    /// Milliseconds since the epoch (UTC) when the value was acquired.
    #[prost(uint64, optional, tag = "3")]
    pub timestamp: Option<u64>,
    /// A [`DataType`] number.
    #[prost(uint32, optional, tag = "4")]
    pub datatype: Option<u32>,
    /// Stored and forwarded: must not update the live value (§6.4.4, §11 store and forward).
    #[prost(bool, optional, tag = "5")]
    pub is_historical: Option<bool>,
    #[prost(bool, optional, tag = "6")]
    pub is_transient: Option<bool>,
    #[prost(bool, optional, tag = "7")]
    pub is_null: Option<bool>,
    #[prost(message, optional, tag = "9")]
    pub properties: Option<PropertySet>,
    #[prost(oneof = "Value", tags = "10, 11, 12, 13, 14, 15, 16")]
    pub value: Option<Value>,
}

/// `Metric.value` (§6.4.4).
#[derive(Clone, PartialEq, prost::Oneof)]
pub enum Value {
    #[prost(uint32, tag = "10")]
    Int(u32),
    #[prost(uint64, tag = "11")]
    Long(u64),
    #[prost(float, tag = "12")]
    Float(f32),
    #[prost(double, tag = "13")]
    Double(f64),
    #[prost(bool, tag = "14")]
    Boolean(bool),
    #[prost(string, tag = "15")]
    String(String),
    #[prost(bytes = "vec", tag = "16")]
    Bytes(Vec<u8>),
}

/// `Payload.PropertySet` (§6.4.6): the engineering unit goes here (`engUnit`).
#[derive(Clone, PartialEq, prost::Message)]
pub struct PropertySet {
    #[prost(string, repeated, tag = "1")]
    pub keys: Vec<String>,
    #[prost(message, repeated, tag = "2")]
    pub values: Vec<PropertyValue>,
}

/// `Payload.PropertyValue` (§6.4.7).
#[derive(Clone, PartialEq, prost::Message)]
pub struct PropertyValue {
    #[prost(uint32, optional, tag = "1")]
    pub r#type: Option<u32>,
    #[prost(bool, optional, tag = "2")]
    pub is_null: Option<bool>,
    #[prost(oneof = "PropertyKind", tags = "3, 4, 5, 6, 7, 8")]
    pub value: Option<PropertyKind>,
}

/// `PropertyValue.value` (§6.4.7), the scalar kinds.
#[derive(Clone, PartialEq, prost::Oneof)]
pub enum PropertyKind {
    #[prost(uint32, tag = "3")]
    Int(u32),
    #[prost(uint64, tag = "4")]
    Long(u64),
    #[prost(float, tag = "5")]
    Float(f32),
    #[prost(double, tag = "6")]
    Double(f64),
    #[prost(bool, tag = "7")]
    Boolean(bool),
    #[prost(string, tag = "8")]
    String(String),
}

/// Data type numbers (Sparkplug 3.0 §6.4.16), the ones mbtap uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataType {
    Int64 = 4,
    UInt64 = 8,
    Double = 10,
    Boolean = 11,
    String = 12,
}

impl DataType {
    /// Its number on the wire.
    #[must_use]
    pub const fn code(self) -> u32 {
        self as u32
    }
}

impl Payload {
    /// The protobuf bytes.
    #[must_use]
    pub fn to_bytes(&self) -> Vec<u8> {
        self.encode_to_vec()
    }

    /// Reads a payload (an NCMD or DCMD from the broker, any bytes).
    ///
    /// # Errors
    /// Bytes that are not a protobuf `Payload`, with prost's account of where.
    pub fn parse_payload(bytes: &[u8]) -> Result<Self, prost::DecodeError> {
        Self::decode(bytes)
    }
}

/// A metric's value as JSON-ish mbtap values map onto Sparkplug types: bits are Boolean,
/// integers Int64 (negative) or UInt64, scaled numbers Double, labels and text String.
#[must_use]
pub fn value_of(v: &serde_json::Value, bits: bool) -> (DataType, Option<Value>) {
    match v {
        serde_json::Value::Bool(b) => (DataType::Boolean, Some(Value::Boolean(*b))),
        serde_json::Value::Number(n) if bits => (DataType::Boolean, Some(Value::Boolean(n.as_f64() != Some(0.0)))),
        // Int64 travels as its two's complement in `long_value` (Sparkplug 3.0 §6.4.16).
        serde_json::Value::Number(n) if n.is_i64() && n.as_i64().is_some_and(|i| i < 0) => {
            (DataType::Int64, n.as_i64().map(|i| Value::Long(i.cast_unsigned())))
        }
        serde_json::Value::Number(n) if n.is_u64() => (DataType::UInt64, n.as_u64().map(Value::Long)),
        serde_json::Value::Number(n) => (DataType::Double, n.as_f64().map(Value::Double)),
        serde_json::Value::String(s) => (DataType::String, Some(Value::String(s.clone()))),
        serde_json::Value::Null => (DataType::Double, None),
        other => (DataType::String, Some(Value::String(other.to_string()))),
    }
}
