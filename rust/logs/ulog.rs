//! PX4 ULog (`.ulg`): message framing and field decoding, in one pass over the file.
//!
//! Format (PX4 "ULog File Format", dev guide): a 16-byte header (magic `ULog\x01\x12\x35`,
//! version, start time in µs), then messages of `u16 size, u8 type, payload[size]`, little
//! endian. The definitions section (flag bits `B`, formats `F`, information `I`/`M`, initial
//! parameters `P`, default parameters `Q`) ends at the first subscription `A` or log text
//! `L`/`C`; the data section holds subscriptions `A` (message id -> format and instance),
//! data `D` (message id + one row of the format, packed, no trailing padding), changed
//! parameters `P`, dropouts `O`, sync markers `S` and more information.
//!
//! Damage is handled as pyulog 1.x handles it, so that the same file gives the same result
//! with either reader: a malformed message in the definitions is skipped; in the data section
//! a payload too short for its fixed part ends the read (pyulog's `struct.error`), while a
//! row of the wrong size, a subscription to an unknown format or a data message without a
//! subscription only marks the file corrupt; an unknown message type with a zero or
//! oversized (> 10,000 bytes) size is taken for lost framing: the read moves on by one byte
//! and searches for the next sync marker. The fatal cases are a bad header, an unknown
//! incompatible flag, a format that contains itself and framing that points before the start
//! of the file.

use super::{le, utf8_ignore, Column, Source, Value};
use crate::error::{CalError, Result};
use std::collections::{HashMap, HashSet};
use std::path::Path;

const MAGIC: &[u8; 7] = b"ULog\x01\x12\x35";
const SYNC: [u8; 8] = [0x2F, 0x73, 0x13, 0x20, 0x25, 0x0C, 0xBB, 0x12];
/// Nested formats deeper than this are taken for a format that contains itself (Python's
/// recursion limit stops pyulog at about 1,000).
const MAX_DEPTH: usize = 900;
/// Most fields a flattened format may have (a few hundred in practice; a damaged array size
/// could ask for billions).
const MAX_FIELDS: usize = 1 << 20;

/// The basic field types of a ULog format.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum FieldType {
    /// int8_t
    I8,
    /// uint8_t
    U8,
    /// int16_t
    I16,
    /// uint16_t
    U16,
    /// int32_t
    I32,
    /// uint32_t
    U32,
    /// int64_t
    I64,
    /// uint64_t
    U64,
    /// float
    F32,
    /// double
    F64,
    /// bool (stored as int8, as pyulog does)
    Bool,
    /// char (stored as int8, as pyulog does)
    Char,
}

impl FieldType {
    fn parse(s: &str) -> Option<FieldType> {
        Some(match s {
            "int8_t" => FieldType::I8,
            "uint8_t" => FieldType::U8,
            "int16_t" => FieldType::I16,
            "uint16_t" => FieldType::U16,
            "int32_t" => FieldType::I32,
            "uint32_t" => FieldType::U32,
            "int64_t" => FieldType::I64,
            "uint64_t" => FieldType::U64,
            "float" => FieldType::F32,
            "double" => FieldType::F64,
            "bool" => FieldType::Bool,
            "char" => FieldType::Char,
            _ => return None,
        })
    }

    /// Size in bytes.
    pub fn size(self) -> usize {
        match self {
            FieldType::I8 | FieldType::U8 | FieldType::Bool | FieldType::Char => 1,
            FieldType::I16 | FieldType::U16 => 2,
            FieldType::I32 | FieldType::U32 | FieldType::F32 => 4,
            FieldType::I64 | FieldType::U64 | FieldType::F64 => 8,
        }
    }

    fn column(self) -> Column {
        match self {
            FieldType::I8 | FieldType::Bool | FieldType::Char => Column::I8(Vec::new()),
            FieldType::U8 => Column::U8(Vec::new()),
            FieldType::I16 => Column::I16(Vec::new()),
            FieldType::U16 => Column::U16(Vec::new()),
            FieldType::I32 => Column::I32(Vec::new()),
            FieldType::U32 => Column::U32(Vec::new()),
            FieldType::I64 => Column::I64(Vec::new()),
            FieldType::U64 => Column::U64(Vec::new()),
            FieldType::F32 => Column::F32(Vec::new()),
            FieldType::F64 => Column::F64(Vec::new()),
        }
    }

    /// The value of a metadata message of this type (Python's `struct.unpack`), if `b` is
    /// exactly its size.
    fn value(self, b: &[u8]) -> Option<Value> {
        if b.len() != self.size() {
            return None;
        }
        Some(match self {
            FieldType::I8 => Value::Int(b[0] as i8 as i64),
            FieldType::U8 => Value::Int(b[0] as i64),
            FieldType::I16 => Value::Int(i16::from_le_bytes(le(b, 0)) as i64),
            FieldType::U16 => Value::Int(u16::from_le_bytes(le(b, 0)) as i64),
            FieldType::I32 => Value::Int(i32::from_le_bytes(le(b, 0)) as i64),
            FieldType::U32 => Value::Int(u32::from_le_bytes(le(b, 0)) as i64),
            FieldType::I64 => Value::Int(i64::from_le_bytes(le(b, 0))),
            FieldType::U64 => Value::UInt(u64::from_le_bytes(le(b, 0))),
            FieldType::F32 => Value::Float(f32::from_le_bytes(le(b, 0)) as f64),
            FieldType::F64 => Value::Float(f64::from_le_bytes(le(b, 0))),
            FieldType::Bool => Value::Bool(b[0] != 0),
            FieldType::Char => Value::Bytes(b.to_vec()),
        })
    }
}

/// One decoded topic instance: pyulog's `ULog.Data`.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// Topic name.
    pub name: String,
    /// Instance (`multi_id`).
    pub multi_id: u8,
    /// Message id of its subscription.
    pub msg_id: u16,
    /// Columns by field name (numpy's names: an empty name becomes `f<i>`), in format order.
    pub fields: Vec<(String, Column)>,
}

/// What a ULog holds, as far as the calibration reader needs it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ULog {
    /// Start time, µs.
    pub start_timestamp: u64,
    /// Information messages, key -> value (the last one of a key wins; first-seen order).
    pub info: Vec<(String, Value)>,
    /// Parameters of the definitions section, name -> value (same rules).
    pub initial_parameters: Vec<(String, Value)>,
    /// Parameters changed in the data section: (time of the latest data, name, value).
    pub changed_parameters: Vec<(u64, String, Value)>,
    /// The decoded topics, sorted by (name, instance) as pyulog sorts them.
    pub datasets: Vec<Dataset>,
    /// Whether damage was seen (pyulog's `file_corruption`).
    pub corrupt: bool,
    /// The file has data appended at offsets given by its flag bits (a rare layout this
    /// reader leaves to pyulog); nothing past the definitions was read.
    pub appended: bool,
}

/// The Python exceptions pyulog's message parsers raise on damage: they decide whether a
/// message is skipped (`Index`, `Key`, `Value`) or, in the data section, ends the read
/// (`Struct`, as `struct.error`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Py {
    Struct,
    Index,
    Key,
    Value,
}

/// An error while flattening a format.
enum Flat {
    /// A caught exception (a missing nested format, an invalid field list).
    Caught(Py),
    /// A format that contains itself (pyulog: `RecursionError`, which ends the whole read), or
    /// one with more fields than any log has.
    Fatal(String),
}

type Fields = Vec<(String, u32, String)>; // (type, array size, name)

/// First-seen order, last value wins: a Python dict.
#[derive(Default)]
struct Dict {
    items: Vec<(String, Value)>,
    index: HashMap<String, usize>,
}

impl Dict {
    fn set(&mut self, k: String, v: Value) {
        match self.index.get(&k) {
            Some(&i) => self.items[i].1 = v,
            None => {
                self.index.insert(k.clone(), self.items.len());
                self.items.push((k, v));
            }
        }
    }
}

/// Python's `str.split(" ")`'s first two parts, if there are two.
fn two_words(s: &str) -> Option<(&str, &str)> {
    let mut it = s.split(' ');
    let a = it.next()?;
    let b = it.next()?;
    Some((a, b))
}

/// Python's `int(s)` for a decimal string (whitespace, a sign, digits with single
/// underscores between them); `None` where Python raises `ValueError`. (Python also takes
/// non-ASCII decimal digits, which no log writes.)
fn py_int(s: &str) -> Option<i64> {
    let ws = |c: char| c.is_whitespace() || ('\u{1c}'..='\u{1f}').contains(&c);
    let t = s.trim_matches(ws);
    let (neg, digits) = match t.strip_prefix('-') {
        Some(r) => (true, r),
        None => (false, t.strip_prefix('+').unwrap_or(t)),
    };
    if digits.is_empty() || digits.starts_with('_') || digits.ends_with('_') {
        return None;
    }
    let mut v: i64 = 0;
    let mut prev_us = false;
    for c in digits.chars() {
        if c == '_' {
            if prev_us {
                return None;
            }
            prev_us = true;
            continue;
        }
        prev_us = false;
        let d = c.to_digit(10)? as i64;
        v = v.saturating_mul(10).saturating_add(d);
    }
    Some(if neg { -v } else { v })
}

/// A format message `name:type field;type[n] field;...` (pyulog's `MessageFormat`).
fn parse_format(data: &[u8]) -> std::result::Result<(String, Fields), Py> {
    let s = utf8_ignore(data);
    let mut parts = s.split(':');
    let name = parts.next().unwrap_or("").to_string();
    let types = parts.next().ok_or(Py::Index)?;
    let mut fields = Vec::new();
    for t in types.split(';').filter(|t| !t.is_empty()) {
        let (type_str, name_str) = two_words(t).ok_or(Py::Index)?;
        let chars: Vec<char> = type_str.chars().collect();
        let a = chars.iter().position(|&c| c == '[');
        let (ty, size) = match a {
            None => (type_str.to_string(), 0u32),
            Some(a) => {
                // type_str[a + 1:b] with Python's slice rules (b = -1 when there is no ']')
                let n = chars.len() as i64;
                let b = chars
                    .iter()
                    .position(|&c| c == ']')
                    .map_or(-1, |b| b as i64);
                let end = if b < 0 { n + b } else { b }.clamp(0, n) as usize;
                let start = (a + 1).min(chars.len());
                let inner: String = if start < end {
                    chars[start..end].iter().collect()
                } else {
                    String::new()
                };
                let size = py_int(&inner).ok_or(Py::Value)?;
                if !(0..=0xFFFF).contains(&size) {
                    return Err(Py::Value);
                }
                (chars[..a].iter().collect(), size as u32)
            }
        };
        fields.push((ty, size, name_str.to_string()));
    }
    Ok((name, fields))
}

/// An information message (`I`, and the body of `M`, `P`, `Q`): (type, key, value).
fn parse_info(data: &[u8]) -> std::result::Result<(String, String, Value), Py> {
    let key_len = *data.first().ok_or(Py::Struct)? as usize;
    let type_key = utf8_ignore(&data[1..(1 + key_len).min(data.len())]);
    let (ty, key) = two_words(&type_key).ok_or(Py::Index)?;
    let rest = data.get(1 + key_len..).unwrap_or(&[]);
    let value = if ty.starts_with("char[") {
        Value::Str(utf8_ignore(rest))
    } else if let Some(ft) = FieldType::parse(ty) {
        ft.value(rest).ok_or(Py::Struct)?
    } else {
        Value::Bytes(rest.to_vec())
    };
    Ok((ty.to_string(), key.to_string(), value))
}

/// A subscription: the flattened format of a topic and its decoded columns so far.
struct Sub {
    name: String,
    multi_id: u8,
    msg_id: u16,
    /// (numpy name, type, offset in the row)
    fields: Vec<(String, FieldType, usize)>,
    itemsize: usize,
    t_off: usize,
    columns: Vec<Column>,
    rows: usize,
}

impl Sub {
    fn push_row(&mut self, row: &[u8]) {
        for ((_, ty, off), col) in self.fields.iter().zip(self.columns.iter_mut()) {
            let o = *off;
            match (ty, col) {
                (FieldType::I8 | FieldType::Bool | FieldType::Char, Column::I8(v)) => {
                    v.push(row[o] as i8)
                }
                (FieldType::U8, Column::U8(v)) => v.push(row[o]),
                (FieldType::I16, Column::I16(v)) => v.push(i16::from_le_bytes(le(row, o))),
                (FieldType::U16, Column::U16(v)) => v.push(u16::from_le_bytes(le(row, o))),
                (FieldType::I32, Column::I32(v)) => v.push(i32::from_le_bytes(le(row, o))),
                (FieldType::U32, Column::U32(v)) => v.push(u32::from_le_bytes(le(row, o))),
                (FieldType::I64, Column::I64(v)) => v.push(i64::from_le_bytes(le(row, o))),
                (FieldType::U64, Column::U64(v)) => v.push(u64::from_le_bytes(le(row, o))),
                (FieldType::F32, Column::F32(v)) => v.push(f32::from_le_bytes(le(row, o))),
                (FieldType::F64, Column::F64(v)) => v.push(f64::from_le_bytes(le(row, o))),
                _ => unreachable!("columns are made from the field types"),
            }
        }
        self.rows += 1;
    }
}

/// Flattens a (possibly nested) format into basic fields: pyulog's `_parse_nested_type`.
fn flatten(
    formats: &HashMap<String, Fields>,
    prefix: &str,
    type_name: &str,
    out: &mut Vec<(String, FieldType)>,
    depth: usize,
    budget: &mut usize,
) -> std::result::Result<(), Flat> {
    if *budget == 0 {
        return Err(Flat::Fatal(format!(
            "the format {type_name:?} would have more than {MAX_FIELDS} fields"
        )));
    }
    *budget -= 1;
    if depth > MAX_DEPTH {
        return Err(Flat::Fatal(format!(
            "the format {type_name:?} contains itself (nested more than {MAX_DEPTH} deep)"
        )));
    }
    let fields = formats.get(type_name).ok_or(Flat::Caught(Py::Key))?;
    for (ty, size, name) in fields {
        let basic = FieldType::parse(ty);
        let reps = if *size > 0 { *size as usize } else { 0 };
        match basic {
            Some(ft) => {
                if out.len() + reps.max(1) > MAX_FIELDS {
                    return Err(Flat::Fatal(format!(
                        "the format {type_name:?} would have more than {MAX_FIELDS} fields"
                    )));
                }
                if *size > 0 {
                    for i in 0..reps {
                        out.push((format!("{prefix}{name}[{i}]"), ft));
                    }
                } else {
                    out.push((format!("{prefix}{name}"), ft));
                }
            }
            None => {
                if *size > 0 {
                    for i in 0..reps {
                        flatten(
                            formats,
                            &format!("{prefix}{name}[{i}]."),
                            ty,
                            out,
                            depth + 1,
                            budget,
                        )?;
                    }
                } else {
                    flatten(
                        formats,
                        &format!("{prefix}{name}."),
                        ty,
                        out,
                        depth + 1,
                        budget,
                    )?;
                }
            }
        }
    }
    Ok(())
}

/// A subscription message (`A`): pyulog's `_MessageAddLogged`.
fn subscription(
    data: &[u8],
    formats: &HashMap<String, Fields>,
) -> std::result::Result<std::result::Result<Sub, Py>, String> {
    let Some(&multi_id) = data.first() else {
        return Ok(Err(Py::Struct));
    };
    if data.len() < 3 {
        return Ok(Err(Py::Struct));
    }
    let msg_id = u16::from_le_bytes(le(data, 1));
    let name = utf8_ignore(&data[3..]);
    let mut flat = Vec::new();
    let mut budget = MAX_FIELDS;
    match flatten(formats, "", &name, &mut flat, 0, &mut budget) {
        Ok(()) => {}
        Err(Flat::Caught(e)) => return Ok(Err(e)),
        Err(Flat::Fatal(why)) => return Err(why),
    }
    while flat.last().is_some_and(|(n, _)| n.starts_with("_padding")) {
        flat.pop();
    }
    let mut t_off = 0;
    for (n, ft) in &flat {
        if n == "timestamp" {
            break;
        }
        t_off += ft.size();
    }
    // numpy's structured dtype: an empty name becomes f<i>; a repeated name is a ValueError
    let mut seen = HashSet::new();
    let mut fields = Vec::with_capacity(flat.len());
    let mut off = 0;
    for (i, (n, ft)) in flat.into_iter().enumerate() {
        let n = if n.is_empty() { format!("f{i}") } else { n };
        if !seen.insert(n.clone()) {
            return Ok(Err(Py::Value));
        }
        fields.push((n, ft, off));
        off += ft.size();
    }
    let columns = fields.iter().map(|(_, ft, _)| ft.column()).collect();
    Ok(Ok(Sub {
        name,
        multi_id,
        msg_id,
        fields,
        itemsize: off,
        t_off,
        columns,
        rows: 0,
    }))
}

/// Reads a ULog, decoding the topics named in `topics` (all topics when `None`).
///
/// Errors: a file that cannot be opened or read, a bad header, an unknown incompatible flag,
/// a format that contains itself, framing that points before the start of the file, or a
/// definitions section that would be read forever (pyulog loops on it).
pub fn read(path: &Path, topics: Option<&[&str]>) -> Result<ULog> {
    let bad = |why: String| CalError::InvalidArgument(why);
    let mut src = Source::open(path)?;
    let header = src.read(16)?;
    if header.len() != 16 {
        return Err(bad("invalid file format (header too short)".into()));
    }
    if &header[..7] != MAGIC {
        return Err(bad("invalid file format (failed to parse header)".into()));
    }
    let start_timestamp = u64::from_le_bytes(le(header, 8));

    let mut formats: HashMap<String, Fields> = HashMap::new();
    let mut info = Dict::default();
    let mut params = Dict::default();
    let mut corrupt = false;
    let mut incompat = [0u8; 8];
    let mut appended_offsets: Vec<u64> = Vec::new();
    let mut msg: Vec<u8> = Vec::new();

    // ---- definitions
    let mut seen_tops: HashSet<u64> = HashSet::new();
    let mut went_back = false;
    loop {
        let top = src.tell();
        if went_back && !seen_tops.insert(top) {
            return Err(bad(
                "the definitions section is damaged near the end of the file: its framing \
                 loops back on itself"
                    .into(),
            ));
        }
        let h = src.read(3)?;
        if h.is_empty() {
            break;
        }
        if h.len() < 3 {
            corrupt = true; // struct.error on the header, caught
            continue;
        }
        let size = u16::from_le_bytes(le(h, 0)) as usize;
        let kind = h[2];
        msg.clear();
        msg.extend_from_slice(src.read(size)?);
        let got = msg.len();
        let parsed: std::result::Result<(), Py> = match kind {
            b'I' => parse_info(&msg).map(|(_, k, v)| info.set(k, v)),
            b'M' => {
                if msg.is_empty() {
                    Err(Py::Struct)
                } else {
                    parse_info(&msg[1..]).map(|_| ())
                }
            }
            b'F' => parse_format(&msg).map(|(name, fields)| {
                formats.insert(name, fields);
            }),
            b'P' => parse_info(&msg).map(|(_, k, v)| params.set(k, v)),
            b'Q' => {
                if msg.is_empty() {
                    Err(Py::Struct)
                } else {
                    parse_info(&msg[1..]).map(|_| ())
                }
            }
            b'A' | b'L' | b'C' => {
                src.seek(src.tell() as i128 - (3 + size) as i128)?;
                break;
            }
            b'B' => {
                // compat flags, incompatible flags, three appended offsets: 40 bytes
                if got < 40 {
                    Err(Py::Struct)
                } else {
                    incompat.copy_from_slice(&msg[8..16]);
                    appended_offsets = (0..3)
                        .map(|k| u64::from_le_bytes(le(&msg, 16 + 8 * k)))
                        .collect();
                    while appended_offsets.last() == Some(&0) {
                        appended_offsets.pop();
                    }
                    if incompat[0] & !1 != 0 || incompat[1..].iter().any(|&b| b != 0) {
                        return Err(bad(
                            "unknown incompatible flag set: this ULog uses a format extension \
                             that cannot be read"
                                .into(),
                        ));
                    }
                    Ok(())
                }
            }
            _ => {
                if kind == 0 || size == 0 || size > 10_000 {
                    corrupt = true;
                    // back to one byte past this header (further back after a short read)
                    let back = src.tell() as i128 - 2 - size as i128;
                    if got < size {
                        went_back = true;
                    }
                    src.seek(back)?;
                }
                Ok(())
            }
        };
        if parsed.is_err() {
            corrupt = true;
        }
    }

    if incompat[0] & 1 != 0 && !appended_offsets.is_empty() {
        return Ok(ULog {
            start_timestamp,
            appended: true,
            ..Default::default()
        });
    }

    // ---- data
    let mut subs: Vec<Sub> = Vec::new();
    // message id -> index into subs + 1 (0: none), and the filtered ids, as flat tables
    let mut sub_of: Vec<u32> = vec![0; 1 << 16];
    let mut filtered: Vec<bool> = vec![false; 1 << 16];
    let mut changed = Vec::new();
    let mut last_ts = start_timestamp;
    let mut has_sync = true;
    loop {
        let h = src.read(3)?;
        if h.len() < 3 {
            break; // struct.error on the header: the end
        }
        let size = u16::from_le_bytes(le(h, 0)) as usize;
        let kind = h[2];
        let msg = src.read(size)?;
        if msg.len() < size {
            break; // cut short: the end
        }
        let outcome: std::result::Result<(), Py> = match kind {
            b'I' => parse_info(msg).map(|(_, k, v)| info.set(k, v)),
            b'M' | b'Q' => {
                if msg.is_empty() {
                    Err(Py::Struct)
                } else {
                    parse_info(&msg[1..]).map(|_| ())
                }
            }
            b'P' => parse_info(msg).map(|(_, k, v)| changed.push((last_ts, k, v))),
            b'A' => match subscription(msg, &formats) {
                Err(why) => return Err(bad(why)),
                Ok(Err(e)) => Err(e),
                Ok(Ok(sub)) => {
                    let wanted = topics.is_none_or(|t| t.contains(&sub.name.as_str()));
                    if wanted {
                        let id = sub.msg_id as usize;
                        match sub_of[id] {
                            0 => {
                                subs.push(sub);
                                sub_of[id] = subs.len() as u32;
                            }
                            i => subs[i as usize - 1] = sub,
                        }
                    } else {
                        filtered[sub.msg_id as usize] = true;
                    }
                    Ok(())
                }
            },
            b'L' => {
                if msg.len() < 9 {
                    Err(Py::Struct)
                } else {
                    Ok(())
                }
            }
            b'C' => {
                if msg.len() < 11 {
                    Err(Py::Struct)
                } else {
                    Ok(())
                }
            }
            b'D' => {
                if msg.len() < 2 {
                    Err(Py::Struct)
                } else {
                    let id = u16::from_le_bytes(le(msg, 0)) as usize;
                    let mut ts = 0u64;
                    let mut damaged = false;
                    let mut end = false;
                    match sub_of[id] {
                        0 => damaged = !filtered[id],
                        i => {
                            let s = &mut subs[i as usize - 1];
                            if msg.len() - 2 != s.itemsize {
                                damaged = true;
                            } else {
                                s.push_row(&msg[2..]);
                                let t = 2 + s.t_off;
                                if t + 8 <= msg.len() {
                                    ts = u64::from_le_bytes(le(msg, t));
                                } else {
                                    end = true;
                                }
                            }
                        }
                    }
                    if end {
                        Err(Py::Struct)
                    } else {
                        if damaged {
                            corrupt = true;
                        } else if ts > last_ts {
                            last_ts = ts;
                        }
                        Ok(())
                    }
                }
            }
            b'O' => {
                if msg.len() != 2 {
                    Err(Py::Struct)
                } else {
                    Ok(())
                }
            }
            b'S' => Ok(()),
            _ => {
                if kind == 0 || size == 0 || size > 10_000 {
                    corrupt = true;
                    src.seek(src.tell() as i128 - 2 - size as i128)?;
                    if has_sync {
                        has_sync = find_sync(&mut src, None, &mut corrupt)?;
                    }
                } else if has_sync {
                    find_sync(&mut src, Some(size), &mut corrupt)?;
                }
                Ok(())
            }
        };
        match outcome {
            Ok(()) => {}
            Err(Py::Struct) => break,
            Err(Py::Index | Py::Key | Py::Value) => corrupt = true,
        }
    }

    // pyulog: popitem() (last subscribed first), then a stable sort by (name, instance)
    let mut datasets: Vec<Dataset> = subs
        .into_iter()
        .rev()
        .filter(|s| s.rows > 0 && s.itemsize > 0)
        .map(|s| Dataset {
            name: s.name,
            multi_id: s.multi_id,
            msg_id: s.msg_id,
            fields: s.fields.into_iter().map(|f| f.0).zip(s.columns).collect(),
        })
        .collect();
    datasets.sort_by(|a, b| (&a.name, a.multi_id).cmp(&(&b.name, b.multi_id)));
    Ok(ULog {
        start_timestamp,
        info: info.items,
        initial_parameters: params.items,
        changed_parameters: changed,
        datasets,
        corrupt,
        appended: false,
    })
}

/// Searches forward for the sync marker (`last` = `Some(n)`: only in the `n` bytes before the
/// current position, the payload just read) and stops right after it; where it is not found
/// the position is left as it was. Returns false when a search to the end found nothing
/// (pyulog then stops searching for good).
fn find_sync(src: &mut Source, last: Option<usize>, corrupt: &mut bool) -> Result<bool> {
    let initial = src.tell();
    let start = match last {
        Some(n) => initial as i128 - n as i128,
        None => initial as i128,
    };
    src.seek(start)?;
    let start = src.tell();
    let limit = match last {
        Some(n) => n,
        None => usize::MAX,
    };
    // scan in chunks, keeping the last 7 bytes so that no marker is split
    let mut pos = start;
    let mut scanned = 0usize;
    let found = loop {
        let want = (limit - scanned).min(super::WINDOW);
        src.seek(pos as i128)?;
        let chunk = src.read(want)?;
        if chunk.len() < SYNC.len() {
            break None;
        }
        if let Some(i) = chunk.windows(SYNC.len()).position(|w| w == SYNC) {
            break Some(pos + i as u64);
        }
        if last.is_some() {
            break None;
        }
        let step = chunk.len() - (SYNC.len() - 1);
        pos += step as u64;
        scanned += step;
    };
    match found {
        Some(at) => {
            src.seek(at as i128 + SYNC.len() as i128)?;
            *corrupt = true;
            Ok(true)
        }
        None => {
            src.seek(initial as i128)?;
            Ok(last.is_some())
        }
    }
}

#[cfg(test)]
#[path = "ulog_tests.rs"]
mod tests;
