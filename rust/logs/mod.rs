//! Autopilot logs read in one streaming pass: PX4 ULog (`ulog`) and ArduPilot DataFlash
//! (`dataflash`).
//!
//! Both readers reproduce, message for message, what the reference Python readers make of a
//! file (pyulog 1.x and pymavlink's `DFReader_binary`), damaged files included: the same
//! messages are kept, skipped or end the read, so that `triaxcal.read_log` returns the same
//! arrays whichever reader ran (`tests/test_logs_core.py` checks this on a corpus of damaged
//! logs). Where pymavlink's behaviour depends on damage to the format definitions themselves
//! (rare, and intricate), the DataFlash reader says so and the Python reader falls back to
//! pymavlink.
//!
//! Memory: the file is read through a window of [`WINDOW`] bytes; what is kept is the decoded
//! columns of the requested messages, never the file.

pub mod dataflash;
pub mod ulog;

use crate::error::{CalError, Result};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

/// Bytes of the file held at a time.
pub const WINDOW: usize = 1 << 18;

/// A file read like a Python file object (`read(n)` returns fewer bytes at the end, `seek` to
/// any position at or past the start), through a window of [`WINDOW`] bytes.
pub(crate) struct Source {
    file: File,
    len: u64,
    pos: u64,
    buf: Vec<u8>,
    buf_start: u64,
}

impl Source {
    pub(crate) fn open(path: &Path) -> Result<Source> {
        let file = File::open(path).map_err(|e| {
            CalError::InvalidArgument(format!("cannot open {}: {e}", path.display()))
        })?;
        let len = file
            .metadata()
            .map_err(|e| CalError::InvalidArgument(format!("cannot read {}: {e}", path.display())))?
            .len();
        Ok(Source {
            file,
            len,
            pos: 0,
            buf: Vec::new(),
            buf_start: 0,
        })
    }

    /// Length of the file in bytes.
    pub(crate) fn len(&self) -> u64 {
        self.len
    }

    /// The current position.
    pub(crate) fn tell(&self) -> u64 {
        self.pos
    }

    /// Moves to `pos` (past the end is allowed; before the start is an error, as in Python).
    pub(crate) fn seek(&mut self, pos: i128) -> Result<()> {
        if pos < 0 {
            return Err(CalError::InvalidArgument(
                "the file's framing points before its start (negative seek)".into(),
            ));
        }
        self.pos = u64::try_from(pos).unwrap_or(u64::MAX);
        Ok(())
    }

    /// Up to `n` bytes from the current position (fewer at the end of the file), advancing.
    pub(crate) fn read(&mut self, n: usize) -> Result<&[u8]> {
        let avail = self.len.saturating_sub(self.pos);
        let n = n.min(usize::try_from(avail).unwrap_or(usize::MAX));
        let end = self.pos + n as u64;
        if !(self.pos >= self.buf_start && end <= self.buf_start + self.buf.len() as u64) {
            self.fill(n)?;
        }
        let off = (self.pos - self.buf_start) as usize;
        self.pos = end;
        Ok(&self.buf[off..off + n])
    }

    /// Loads the window starting at the current position, at least `n` bytes long.
    fn fill(&mut self, n: usize) -> Result<()> {
        let want = n.max(WINDOW);
        let avail = usize::try_from(self.len.saturating_sub(self.pos)).unwrap_or(usize::MAX);
        let size = want.min(avail);
        self.buf.resize(size, 0);
        self.file
            .seek(SeekFrom::Start(self.pos))
            .and_then(|_| self.file.read_exact(&mut self.buf))
            .map_err(|e| CalError::InvalidArgument(format!("reading the log failed: {e}")))?;
        self.buf_start = self.pos;
        Ok(())
    }
}

/// A decoded column of one field.
#[derive(Debug, Clone, PartialEq)]
pub enum Column {
    /// int8 (also bool and char fields of a ULog, as pyulog stores them).
    I8(Vec<i8>),
    /// uint8.
    U8(Vec<u8>),
    /// int16.
    I16(Vec<i16>),
    /// uint16.
    U16(Vec<u16>),
    /// int32.
    I32(Vec<i32>),
    /// uint32.
    U32(Vec<u32>),
    /// int64.
    I64(Vec<i64>),
    /// uint64.
    U64(Vec<u64>),
    /// float32.
    F32(Vec<f32>),
    /// float64.
    F64(Vec<f64>),
    /// Text (DataFlash strings).
    Str(Vec<String>),
}

impl Column {
    /// Number of values.
    pub fn len(&self) -> usize {
        match self {
            Column::I8(v) => v.len(),
            Column::U8(v) => v.len(),
            Column::I16(v) => v.len(),
            Column::U16(v) => v.len(),
            Column::I32(v) => v.len(),
            Column::U32(v) => v.len(),
            Column::I64(v) => v.len(),
            Column::U64(v) => v.len(),
            Column::F32(v) => v.len(),
            Column::F64(v) => v.len(),
            Column::Str(v) => v.len(),
        }
    }

    /// Whether the column is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A scalar value of a log's metadata (an information message or a parameter), as the Python
/// readers give it.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// A whole number.
    Int(i64),
    /// A whole number of 64 bits, unsigned.
    UInt(u64),
    /// A floating-point number (a float32 widened exactly).
    Float(f64),
    /// A boolean.
    Bool(bool),
    /// Text.
    Str(String),
    /// Raw bytes (a value of a type without a plain meaning).
    Bytes(Vec<u8>),
}

/// Bytes decoded as UTF-8 with undecodable bytes dropped (Python's `errors="ignore"`).
pub(crate) fn utf8_ignore(b: &[u8]) -> String {
    let mut s = String::with_capacity(b.len());
    for chunk in b.utf8_chunks() {
        s.push_str(chunk.valid());
    }
    s
}

/// A little-endian reader of fixed-size values from a byte slice.
#[inline(always)]
pub(crate) fn le<const N: usize>(b: &[u8], at: usize) -> [u8; N] {
    let mut a = [0u8; N];
    a.copy_from_slice(&b[at..at + N]);
    a
}
