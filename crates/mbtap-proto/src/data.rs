//! Zero-copy views over the data fields of a PDU: big-endian 16-bit registers, packed bits,
//! and the record lists of functions 0x14, 0x15 and 0x2B/0x0E.

/// Registers as they travel: 16-bit words, high byte first (MAP v1.1b3 §4.2, "big-Endian").
/// An odd trailing byte (possible only in a malformed frame) is kept in [`Self::as_bytes`] and
/// reported by [`Self::odd_byte`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Registers<'a>(&'a [u8]);

impl<'a> Registers<'a> {
    /// Views `bytes` as registers.
    #[must_use]
    pub const fn new(bytes: &'a [u8]) -> Self {
        Self(bytes)
    }

    /// The bytes as on the wire.
    #[must_use]
    pub const fn as_bytes(&self) -> &'a [u8] {
        self.0
    }

    /// Number of whole registers.
    #[must_use]
    pub const fn len(&self) -> usize {
        self.0.len() / 2
    }

    /// True when there is no whole register.
    #[must_use]
    pub const fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The `i`-th register.
    #[must_use]
    pub fn get(&self, i: usize) -> Option<u16> {
        let at = i.checked_mul(2)?;
        let pair = self.0.get(at..at.checked_add(2)?)?;
        Some(u16::from_be_bytes([pair[0], pair[1]]))
    }

    /// Every whole register, in order.
    pub fn iter(&self) -> impl Iterator<Item = u16> + 'a {
        self.0.chunks_exact(2).map(|p| u16::from_be_bytes([p[0], p[1]]))
    }

    /// The last byte when the byte count is odd.
    #[must_use]
    pub fn odd_byte(&self) -> Option<u8> {
        if self.0.len() % 2 == 1 { self.0.last().copied() } else { None }
    }
}

/// Packed bits (coils, discrete inputs): LSB of the first byte is the first bit
/// (MAP v1.1b3 §6.1: "the LSB of the first data byte contains the output addressed in the query").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Bits<'a>(&'a [u8]);

impl<'a> Bits<'a> {
    /// Views `bytes` as packed bits.
    #[must_use]
    pub const fn new(bytes: &'a [u8]) -> Self {
        Self(bytes)
    }

    /// The bytes as on the wire.
    #[must_use]
    pub const fn as_bytes(&self) -> &'a [u8] {
        self.0
    }

    /// Number of bits the bytes can hold (8 per byte; the request's quantity says how many count).
    #[must_use]
    pub const fn capacity(&self) -> usize {
        self.0.len() * 8
    }

    /// The `i`-th bit.
    #[must_use]
    pub fn get(&self, i: usize) -> Option<bool> {
        self.0.get(i / 8).map(|b| (b >> (i % 8)) & 1 == 1)
    }

    /// The first `count` bits (fewer if the bytes run out).
    pub fn iter(&self, count: usize) -> impl Iterator<Item = bool> + 'a {
        let bytes = self.0;
        (0..count.min(bytes.len() * 8)).map(move |i| (bytes[i / 8] >> (i % 8)) & 1 == 1)
    }
}

/// Bytes needed for `quantity` packed bits: N = quantity / 8, +1 if the remainder is not 0
/// (MAP v1.1b3 §6.1).
#[must_use]
pub const fn bit_bytes(quantity: u16) -> usize {
    (quantity as usize).div_ceil(8)
}

/// Reference type of every file sub-request (MAP v1.1b3 §6.14: "must be specified as 6").
pub const FILE_REFERENCE_TYPE: u8 = 6;

/// One sub-request of Read File Record (0x14): 7 bytes on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FileSubRequest {
    pub reference_type: u8,
    pub file_number: u16,
    pub record_number: u16,
    pub record_length: u16,
}

/// The sub-request list of a 0x14 request. Bytes that do not make a whole 7-byte
/// sub-request are left in [`Self::remainder`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FileSubRequests<'a>(&'a [u8]);

impl<'a> FileSubRequests<'a> {
    #[must_use]
    pub const fn new(bytes: &'a [u8]) -> Self {
        Self(bytes)
    }
    #[must_use]
    pub const fn as_bytes(&self) -> &'a [u8] {
        self.0
    }
    pub fn iter(&self) -> impl Iterator<Item = FileSubRequest> + 'a {
        self.0.chunks_exact(7).map(|c| FileSubRequest {
            reference_type: c[0],
            file_number: u16::from_be_bytes([c[1], c[2]]),
            record_number: u16::from_be_bytes([c[3], c[4]]),
            record_length: u16::from_be_bytes([c[5], c[6]]),
        })
    }
    #[must_use]
    pub fn remainder(&self) -> &'a [u8] {
        self.0.chunks_exact(7).remainder()
    }
}

/// A record in Write File Record (0x15) requests and responses, or a sub-response of Read File
/// Record (0x14) (which has no file or record number).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FileRecord<'a> {
    pub reference_type: u8,
    /// `None` in a 0x14 sub-response.
    pub file_number: Option<u16>,
    /// `None` in a 0x14 sub-response.
    pub record_number: Option<u16>,
    pub data: Registers<'a>,
}

/// The record list of 0x15 (both directions) or the sub-responses of a 0x14 response.
/// Iteration stops at the first record that does not fit; [`Self::malformed_at`] says where.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FileRecords<'a> {
    bytes: &'a [u8],
    /// 0x14 response layout (length byte, reference type, data) instead of 0x15's.
    sub_response: bool,
}

impl<'a> FileRecords<'a> {
    /// 0x15 layout: reference type, file number, record number, record length, data.
    #[must_use]
    pub const fn write_layout(bytes: &'a [u8]) -> Self {
        Self { bytes, sub_response: false }
    }
    /// 0x14 response layout: file response length, reference type, data.
    #[must_use]
    pub const fn read_response_layout(bytes: &'a [u8]) -> Self {
        Self { bytes, sub_response: true }
    }
    #[must_use]
    pub const fn as_bytes(&self) -> &'a [u8] {
        self.bytes
    }

    fn next_at(&self, at: usize) -> Option<(FileRecord<'a>, usize)> {
        let rest = self.bytes.get(at..)?;
        if self.sub_response {
            let len = usize::from(*rest.first()?);
            let body = rest.get(1..1usize.checked_add(len)?)?;
            let (&reference_type, data) = body.split_first()?;
            let rec = FileRecord { reference_type, file_number: None, record_number: None, data: Registers::new(data) };
            Some((rec, at + 1 + len))
        } else {
            let head = rest.get(..7)?;
            let record_length = usize::from(u16::from_be_bytes([head[5], head[6]]));
            let data_len = record_length.checked_mul(2)?;
            let data = rest.get(7..7usize.checked_add(data_len)?)?;
            let rec = FileRecord {
                reference_type: head[0],
                file_number: Some(u16::from_be_bytes([head[1], head[2]])),
                record_number: Some(u16::from_be_bytes([head[3], head[4]])),
                data: Registers::new(data),
            };
            Some((rec, at + 7 + data_len))
        }
    }

    /// The records that fit, in order.
    pub fn iter(&self) -> impl Iterator<Item = FileRecord<'a>> + '_ {
        let mut at = 0;
        std::iter::from_fn(move || {
            let (rec, next) = self.next_at(at)?;
            at = next;
            Some(rec)
        })
    }

    /// Offset of the first byte that does not form a whole record, if any.
    #[must_use]
    pub fn malformed_at(&self) -> Option<usize> {
        let mut at = 0;
        while at < self.bytes.len() {
            match self.next_at(at) {
                Some((_, next)) => at = next,
                None => return Some(at),
            }
        }
        None
    }
}

/// Object ids of Read Device Identification (MAP v1.1b3 §6.21, table of object ids).
#[must_use]
pub const fn device_object_name(id: u8) -> &'static str {
    match id {
        0x00 => "VendorName",
        0x01 => "ProductCode",
        0x02 => "MajorMinorRevision",
        0x03 => "VendorUrl",
        0x04 => "ProductName",
        0x05 => "ModelName",
        0x06 => "UserApplicationName",
        0x07..=0x7F => "Reserved",
        _ => "Private",
    }
}

/// One object of a Read Device Identification response.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceObject<'a> {
    pub id: u8,
    pub value: &'a [u8],
}

/// The object list of a 0x2B/0x0E response: exactly `count` objects parsed from `bytes`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DeviceObjects<'a> {
    count: u8,
    bytes: &'a [u8],
}

impl<'a> DeviceObjects<'a> {
    /// Splits `count` objects (id, length, value) off the front of `input`: returns the list and
    /// the rest, or `None` when `input` is too short for them.
    #[must_use]
    pub fn split(input: &'a [u8], count: u8) -> Option<(Self, &'a [u8])> {
        let mut at = 0usize;
        for _ in 0..count {
            let len = usize::from(*input.get(at.checked_add(1)?)?);
            at = at.checked_add(2)?.checked_add(len)?;
            if at > input.len() {
                return None;
            }
        }
        let (bytes, rest) = input.split_at(at);
        Some((Self { count, bytes }, rest))
    }

    /// Builds a list from objects, for encoding.
    #[must_use]
    pub const fn from_raw(count: u8, bytes: &'a [u8]) -> Self {
        Self { count, bytes }
    }

    #[must_use]
    pub const fn count(&self) -> u8 {
        self.count
    }

    #[must_use]
    pub const fn as_bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// The objects, in order.
    pub fn iter(&self) -> impl Iterator<Item = DeviceObject<'a>> + 'a {
        let mut rest = self.bytes;
        std::iter::from_fn(move || {
            let (&id, after) = rest.split_first()?;
            let (&len, after) = after.split_first()?;
            let value = after.get(..usize::from(len))?;
            rest = &after[usize::from(len)..];
            Some(DeviceObject { id, value })
        })
    }
}
