//! ArduPilot DataFlash (`.bin`): FMT-driven decoding of the requested messages, in one pass.
//!
//! Format (ArduPilot `AP_Logger`, `LogStructure.h`): messages of `0xA3 0x95 type body`, little
//! endian, each type's body laid out by an `FMT` message (type 0x80: `type u8, length u8,
//! name char[4], format char[16], columns char[64]`, the length counting the 3 header bytes).
//! A format character per column gives its type and scale (`c`: int16 / 100, `L`: int32
//! degrees * 1e7, `n`/`N`/`Z`: text of 4/16/64 bytes...).
//!
//! Framing follows the indexer of pymavlink 2.4.50 (`dfindexer`), so that a damaged file gives
//! the same messages: where the two header bytes are missing the read moves on by one byte
//! ("bad header"); a message starts where they are, and its type's length comes from an `FMT`
//! seen earlier (`FMT` itself is 89 bytes); a type without one, or an `FMT` with a length
//! below 3, ends the read, and so does a message cut by the end of the file. pymavlink then decodes with the *last* definition of each type and
//! behaves in ways that depend on the details of damaged definitions (a length that does not
//! match the format, a type defined twice differently, two types of one name, an odd type for
//! a time or instance column); for such files [`read`] returns [`Outcome::Fallback`] with the
//! reason, and the Python reader hands the file to pymavlink.

use super::{le, Column, Source};
use crate::error::{CalError, Result};
use std::collections::{HashMap, HashSet};
use std::path::Path;

const HEAD1: u8 = 0xA3;
const HEAD2: u8 = 0x95;
const FMT_TYPE: u8 = 0x80;
const FMT_LEN: usize = 89;
/// pymavlink reports skipped bytes only this far from the end (logs often end in garbage).
const TAIL: u64 = 528;

/// One column's type, from its format character.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F16,
    F32,
    F64,
    /// int16 / 100 (`c`), uint16 / 100 (`C`), int32 / 100 (`e`), uint32 / 100 (`E`)
    Centi(u8),
    /// int32 / 1e7 (`L`, latitude and longitude)
    Deg7,
    /// Text of this many bytes.
    Text(usize),
    /// `int16[32]` (`a`).
    Array,
}

impl Kind {
    fn of(c: u8) -> Option<Kind> {
        Some(match c {
            b'a' => Kind::Array,
            b'b' | b'M' => Kind::I8,
            b'B' => Kind::U8,
            b'g' => Kind::F16,
            b'h' => Kind::I16,
            b'H' => Kind::U16,
            b'i' => Kind::I32,
            b'I' => Kind::U32,
            b'f' => Kind::F32,
            b'n' => Kind::Text(4),
            b'N' => Kind::Text(16),
            b'Z' => Kind::Text(64),
            b'c' => Kind::Centi(b'c'),
            b'C' => Kind::Centi(b'C'),
            b'e' => Kind::Centi(b'e'),
            b'E' => Kind::Centi(b'E'),
            b'L' => Kind::Deg7,
            b'd' => Kind::F64,
            b'q' => Kind::I64,
            b'Q' => Kind::U64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Kind::I8 | Kind::U8 => 1,
            Kind::I16 | Kind::U16 | Kind::F16 => 2,
            Kind::I32 | Kind::U32 | Kind::F32 | Kind::Deg7 => 4,
            Kind::I64 | Kind::U64 | Kind::F64 => 8,
            Kind::Centi(c) => match c {
                b'c' | b'C' => 2,
                _ => 4,
            },
            Kind::Text(n) => n,
            Kind::Array => 64,
        }
    }

    fn is_int(self) -> bool {
        matches!(
            self,
            Kind::I8
                | Kind::U8
                | Kind::I16
                | Kind::U16
                | Kind::I32
                | Kind::U32
                | Kind::I64
                | Kind::U64
        )
    }

    fn is_number(self) -> bool {
        !matches!(self, Kind::Text(_) | Kind::Array)
    }
}

/// One `FMT` definition.
#[derive(Debug, Clone, PartialEq)]
struct Format {
    name: String,
    len: usize,
    format: Vec<u8>,
    columns: Vec<String>,
}

impl Format {
    /// Index of a column (the last of that name, as pymavlink's `colhash`).
    fn col(&self, name: &str) -> Option<usize> {
        self.columns.iter().rposition(|c| c == name)
    }
    fn kind(&self, i: usize) -> Option<Kind> {
        self.format.get(i).and_then(|&c| Kind::of(c))
    }
    fn struct_size(&self) -> usize {
        self.format
            .iter()
            .map(|&c| Kind::of(c).map_or(0, Kind::size))
            .sum()
    }
}

/// pymavlink's `null_term` of a text field: decoded (UTF-8, or Latin-1 when that fails, as
/// its message fields are; `backslashreplace` for names), cut at the first NUL.
fn text(b: &[u8], latin1: bool) -> String {
    let s = match std::str::from_utf8(b) {
        Ok(s) => s.to_string(),
        Err(_) if latin1 => b.iter().map(|&c| c as char).collect(),
        Err(_) => {
            // backslashreplace
            let mut s = String::new();
            for chunk in b.utf8_chunks() {
                s.push_str(chunk.valid());
                for &x in chunk.invalid() {
                    s.push_str(&format!("\\x{x:02x}"));
                }
            }
            s
        }
    };
    match s.find('\0') {
        Some(i) => s[..i].to_string(),
        None => s,
    }
}

/// The decoded messages of one type, in file order.
#[derive(Debug, Clone, PartialEq)]
pub struct Messages {
    /// Message name.
    pub name: String,
    /// Columns by name (all but `int16[32]` arrays): integers as int64 (`Q` as uint64),
    /// numbers with a scale or a fraction as float64 (scaled as pymavlink scales them), text
    /// as strings.
    pub columns: Vec<(String, Column)>,
    /// Position of each message among all the messages read (to merge types in file order).
    pub seq: Vec<u64>,
}

/// What [`read`] found.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// The requested messages, in the order of the request (types not in the log are left
    /// out).
    Read {
        /// One entry per requested type present in the log.
        messages: Vec<Messages>,
        /// Bytes skipped because no message header was there (pymavlink's "bad header"
        /// reports).
        bad_headers: u64,
    },
    /// The log's format definitions are damaged in a way whose effect on pymavlink's reading
    /// this reader does not reproduce.
    Fallback(String),
}

struct Decoder {
    name: String,
    /// (column index, kind) of the decoded columns, in column order.
    cols: Vec<(usize, Kind)>,
    offsets: Vec<usize>,
    out: Messages,
}

fn column_of(k: Kind) -> Column {
    match k {
        Kind::Text(_) => Column::Str(Vec::new()),
        Kind::U64 => Column::U64(Vec::new()),
        k if k.is_int() => Column::I64(Vec::new()),
        _ => Column::F64(Vec::new()),
    }
}

impl Decoder {
    fn new(name: &str, f: &Format) -> Decoder {
        let mut cols = Vec::new();
        let mut offsets = Vec::new();
        let mut off = 0;
        let mut offs = Vec::new();
        for &c in &f.format {
            offs.push(off);
            off += Kind::of(c).map_or(0, Kind::size);
        }
        let mut columns = Vec::new();
        for (i, cname) in f.columns.iter().enumerate() {
            if f.col(cname) != Some(i) {
                continue; // a repeated name: pymavlink reads the last one
            }
            let Some(k) = f.kind(i) else { continue };
            if k == Kind::Array {
                continue;
            }
            cols.push((i, k));
            offsets.push(offs[i]);
            columns.push((cname.clone(), column_of(k)));
        }
        Decoder {
            name: name.to_string(),
            cols,
            offsets,
            out: Messages {
                name: name.to_string(),
                columns,
                seq: Vec::new(),
            },
        }
    }

    fn push(&mut self, body: &[u8], seq: u64) {
        for (((_, k), &o), (_, col)) in self
            .cols
            .iter()
            .zip(&self.offsets)
            .zip(self.out.columns.iter_mut())
        {
            let b = &body[o..o + k.size()];
            match (k, col) {
                (Kind::Text(_), Column::Str(v)) => v.push(text(b, true)),
                (Kind::U64, Column::U64(v)) => v.push(u64::from_le_bytes(le(b, 0))),
                (k, Column::I64(v)) => v.push(match k {
                    Kind::I8 => b[0] as i8 as i64,
                    Kind::U8 => b[0] as i64,
                    Kind::I16 => i16::from_le_bytes(le(b, 0)) as i64,
                    Kind::U16 => u16::from_le_bytes(le(b, 0)) as i64,
                    Kind::I32 => i32::from_le_bytes(le(b, 0)) as i64,
                    Kind::U32 => u32::from_le_bytes(le(b, 0)) as i64,
                    _ => i64::from_le_bytes(le(b, 0)),
                }),
                (k, Column::F64(v)) => v.push(match k {
                    Kind::F16 => half(u16::from_le_bytes(le(b, 0))),
                    Kind::F32 => f32::from_le_bytes(le(b, 0)) as f64,
                    Kind::F64 => f64::from_le_bytes(le(b, 0)),
                    // pymavlink divides by 1 / 0.01 = 100.0 and by 1 / 1e-7 (not exactly 1e7)
                    Kind::Centi(b'c') => i16::from_le_bytes(le(b, 0)) as f64 / (1.0 / 0.01),
                    Kind::Centi(b'C') => u16::from_le_bytes(le(b, 0)) as f64 / (1.0 / 0.01),
                    Kind::Centi(b'e') => i32::from_le_bytes(le(b, 0)) as f64 / (1.0 / 0.01),
                    Kind::Centi(_) => u32::from_le_bytes(le(b, 0)) as f64 / (1.0 / 0.01),
                    Kind::Deg7 => i32::from_le_bytes(le(b, 0)) as f64 / (1.0 / 1.0e-7),
                    _ => f64::NAN,
                }),
                _ => unreachable!("columns are made from the kinds"),
            }
        }
        self.out.seq.push(seq);
    }
}

/// IEEE half precision to f64 (Python's `struct` format `e`).
fn half(h: u16) -> f64 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = ((h >> 10) & 0x1f) as i32;
    let frac = (h & 0x3ff) as f64;
    sign * match exp {
        0 => frac * 2f64.powi(-24),
        31 if frac == 0.0 => f64::INFINITY,
        31 => f64::NAN,
        e => (1.0 + frac / 1024.0) * 2f64.powi(e - 15),
    }
}

/// Columns whose odd type would make pymavlink's clock set-up or the reader's own use of them
/// behave differently (time, GPS week and instance columns must be numbers).
const NUMERIC_COLUMNS: [&str; 9] = [
    "TimeUS",
    "TimeMS",
    "GWk",
    "GMS",
    "Week",
    "GPSTime",
    "StartTime",
    "T",
    "I",
];

/// Reads the messages named in `types` from a DataFlash log.
///
/// Errors where pymavlink fails to open the log: a file that cannot be read, an `FMT` with a
/// format character it does not know, a `UNIT` with a negative id, a `FMTU` that names a
/// column the format lacks. Damage to the definitions whose effect this reader does not
/// reproduce gives [`Outcome::Fallback`].
pub fn read(path: &Path, types: &[&str]) -> Result<Outcome> {
    let bad = |why: String| CalError::InvalidArgument(why);
    let mut src = Source::open(path)?;
    let len = src.len();
    let mut lengths = [0usize; 256];
    lengths[FMT_TYPE as usize] = FMT_LEN;
    let mut formats: HashMap<u8, Format> = HashMap::new();
    let mut by_name: HashMap<String, u8> = HashMap::new();
    let mut fmt_done = false; // a cut FMT ends pymavlink's parsing of FMTs
    let mut decoders: HashMap<u8, Decoder> = HashMap::new();
    let mut bad_headers = 0u64;
    let mut units: Vec<i8> = Vec::new(); // ids of the UNIT messages
    let mut fmtus: Vec<Vec<u8>> = Vec::new();
    let mut fmt_at: HashSet<u64> = HashSet::new(); // positions of the indexed FMTs
    let mut counts = [0u64; 256];
    let mut seq = 0u64;
    let mut i = 0u64;
    while i + 3 < len {
        src.seek(i as i128)?;
        let h = src.read(5)?;
        if h[0] != HEAD1 || h[1] != HEAD2 {
            if len - i >= TAIL || len < TAIL {
                bad_headers += 1;
            }
            i += 1;
            continue;
        }
        let mtype = h[2];
        if mtype == FMT_TYPE {
            // dfindexer reads the type and length bytes even at the very end (0 past it)
            let t = h.get(3).copied().unwrap_or(0);
            let l = h.get(4).copied().unwrap_or(0) as usize;
            if l < 3 {
                break; // an invalid FMT length ends the index
            }
            lengths[t as usize] = l;
        }
        let mlen = lengths[mtype as usize];
        if mlen == 0 {
            break; // so does a type without a format
        }
        counts[mtype as usize] += 1;
        if mtype == FMT_TYPE {
            fmt_at.insert(i);
        }
        if mtype == FMT_TYPE && !fmt_done {
            // pymavlink parses every indexed FMT with FMT's own 89 bytes
            src.seek(i as i128 + 3)?;
            let body = src.read(FMT_LEN - 3)?;
            if body.len() < FMT_LEN - 3 {
                fmt_done = true;
            } else {
                let f = Format {
                    name: text(&body[2..6], false),
                    len: body[1] as usize,
                    format: {
                        let raw = &body[6..22];
                        let end = raw.iter().position(|&c| c == 0).unwrap_or(raw.len());
                        raw[..end].to_vec()
                    },
                    columns: {
                        let c = text(&body[22..86], false);
                        if c.is_empty() {
                            Vec::new()
                        } else {
                            c.split(',').map(str::to_string).collect()
                        }
                    },
                };
                if let Some(&c) = f.format.iter().find(|&&c| Kind::of(c).is_none()) {
                    return Err(bad(format!(
                        "message format {:?} uses the unknown format character {:?}",
                        f.name, c as char
                    )));
                }
                let t = body[0];
                if let Some(why) = check_format(t, &f, &formats, &by_name) {
                    return Ok(Outcome::Fallback(why));
                }
                by_name.insert(f.name.clone(), t);
                formats.insert(t, f);
            }
        }
        src.seek(i as i128 + 3)?;
        let body = src.read(mlen - 3)?;
        let complete = body.len() == mlen - 3;
        if !complete {
            break; // a message cut by the end of the file ends pymavlink's read
        }
        if let Some(f) = formats.get(&mtype) {
            match f.name.as_str() {
                "UNIT" => units.push(body.get(8).map_or(0, |&b| b as i8)),
                "FMTU" => fmtus.push(body.to_vec()),
                _ => {}
            }
            if types.contains(&f.name.as_str()) && f.len == f.struct_size() + 3 {
                let d = decoders
                    .entry(mtype)
                    .or_insert_with(|| Decoder::new(&f.name, f));
                d.push(body, seq);
            }
        }
        seq += 1;
        i += mlen as u64;
    }
    // checks on the finished definitions
    for (&t, f) in &formats {
        let visited = types.contains(&f.name.as_str()) || VISITED.contains(&f.name.as_str());
        if f.len != f.struct_size() + 3 && visited && counts[t as usize] > 0 {
            return Ok(Outcome::Fallback(format!(
                "message {:?} is {} bytes long by its FMT but its format {:?} takes {}",
                f.name,
                f.len,
                String::from_utf8_lossy(&f.format),
                f.struct_size() + 3
            )));
        }
        for c in NUMERIC_COLUMNS {
            if let Some(k) = f.col(c).and_then(|i| f.kind(i).or(Some(Kind::Array))) {
                if !k.is_number() {
                    return Ok(Outcome::Fallback(format!(
                        "column {c} of message {:?} is not a number",
                        f.name
                    )));
                }
            }
        }
        if types.contains(&f.name.as_str()) && f.columns.len() > f.format.len() {
            return Ok(Outcome::Fallback(format!(
                "message {:?} has more columns than format characters",
                f.name
            )));
        }
    }
    for (name, want, cols) in [
        ("UNIT", "QbZ", None),
        ("MULT", "Qbd", None),
        ("FMTU", "QBNN", Some("TimeUS,FmtType,UnitIds,MultIds")),
    ] {
        if let Some(f) = by_name.get(name).and_then(|t| formats.get(t)) {
            if f.format != want.as_bytes() || cols.is_some_and(|c| f.columns.join(",") != c) {
                return Ok(Outcome::Fallback(format!(
                    "{name} is not laid out as {want:?}",
                )));
            }
        }
    }
    if let Some(&id) = units.iter().find(|&&u| u < 0) {
        return Err(bad(format!("a UNIT message has the invalid id {id}")));
    }
    let unit_ids: Vec<char> = units.iter().map(|&u| u as u8 as char).collect();
    if let Some(why) = check_fmtus(&fmtus, &formats, &unit_ids)? {
        return Ok(Outcome::Fallback(why));
    }
    if let Some(why) = walk(&mut src, &formats, &fmt_at)? {
        return Ok(Outcome::Fallback(why));
    }
    let mut messages = Vec::new();
    for &name in types {
        if let Some(t) = by_name.get(name) {
            if let Some(d) = decoders.remove(t) {
                debug_assert_eq!(d.name, name);
                messages.push(d.out);
            }
        }
    }
    Ok(Outcome::Read {
        messages,
        bad_headers,
    })
}

/// Message types pymavlink reads by their index besides the requested ones: those its
/// `recv_match` always adds (`MODE`, `MSG`, `PARM`, `STAT`, `ORGN`, `VER`) and those its clock
/// set-up looks for first (`GPS`, `PARM`).
const VISITED: [&str; 7] = ["MODE", "MSG", "PARM", "STAT", "ORGN", "VER", "GPS"];

/// pymavlink's clock set-up reads the log message by message from the start with the final
/// definitions, and a message that does not unpack (its length does not match its format)
/// sends it byte by byte through that message's body. Where that walk would meet an `FMT`
/// the index did not (it would redefine a type with whatever bytes follow) or a damaged
/// `FMTU`, the effect on the result is not reproduced here: the reason is returned.
fn walk(
    src: &mut Source,
    formats: &HashMap<u8, Format>,
    fmt_at: &HashSet<u64>,
) -> Result<Option<String>> {
    let len = src.len();
    let mut pos = 0u64;
    'outer: loop {
        // skip to a header with a known type
        let mtype = loop {
            if len - pos.min(len) < 3 {
                break 'outer;
            }
            src.seek(pos as i128)?;
            let h = src.read(3)?;
            if h[0] == HEAD1 && h[1] == HEAD2 && formats.contains_key(&h[2]) {
                break h[2];
            }
            pos += 1;
        };
        let f = &formats[&mtype];
        let at = pos;
        pos += 3;
        if len - pos < (f.len as u64).saturating_sub(3) || f.len < 3 {
            break; // out of data (pymavlink: None, the walk ends)
        }
        if f.len != f.struct_size() + 3 {
            if len - pos < TAIL {
                break;
            }
            continue; // does not unpack: on from just after its header
        }
        if f.name == "FMT" && !fmt_at.contains(&at) {
            return Ok(Some(format!(
                "pymavlink's first pass would read a format definition at byte {at} that is \
                 not one"
            )));
        }
        if f.name == "FMTU" {
            src.seek(pos as i128)?;
            let b = src.read(8)?;
            let time_us = u64::from_le_bytes(le(b, 0));
            if time_us < 256 && formats.contains_key(&(time_us as u8)) {
                return Ok(Some("a FMTU message has a time below 256 us".into()));
            }
        }
        pos += f.len as u64 - 3;
    }
    Ok(None)
}

/// Why a new definition of type `t` is one this reader does not follow pymavlink through.
fn check_format(
    t: u8,
    f: &Format,
    formats: &HashMap<u8, Format>,
    by_name: &HashMap<String, u8>,
) -> Option<String> {
    if t == FMT_TYPE
        && (f.len != FMT_LEN
            || f.format != b"BBnNZ"
            || f.columns.join(",") != "Type,Length,Name,Format,Columns")
    {
        return Some("the FMT message is redefined".into());
    }
    if let Some(old) = formats.get(&t) {
        if old != f {
            return Some(format!("message type {t} is defined twice, differently"));
        }
    }
    if let Some(&other) = by_name.get(&f.name) {
        if other != t {
            return Some(format!("two message types are named {:?}", f.name));
        }
    }
    None
}

/// pymavlink applies each `FMTU` (units and the instance column of a format) when it opens a
/// log, and fails where one names a column the format does not have (an error here), or,
/// reading the first `FMTU` by position, where its time is below 256 µs and names a type.
fn check_fmtus(
    fmtus: &[Vec<u8>],
    formats: &HashMap<u8, Format>,
    known_units: &[char],
) -> Result<Option<String>> {
    let err = |why: String| Err(CalError::InvalidArgument(why));
    for (n, body) in fmtus.iter().enumerate() {
        // FMTU: TimeUS Q, FmtType B, UnitIds N (16), MultIds N (16)
        let time_us = u64::from_le_bytes(le(body, 0));
        if time_us < 256 && formats.contains_key(&(time_us as u8)) {
            if n == 0 {
                return err("the first FMTU message is damaged (its time is below 256 us)".into());
            }
            return Ok(Some("a FMTU message has a time below 256 us".into()));
        }
        let ftype = body[8];
        let Some(f) = formats.get(&ftype) else {
            continue;
        };
        let unit_ids: Vec<char> = text(&body[9..25], false).chars().collect();
        let mult_ids: Vec<char> = text(&body[25..41], false).chars().collect();
        if let Some(k) = unit_ids.iter().position(|&c| c == '#') {
            if k >= f.columns.len() || k >= f.format.len() {
                return err(format!(
                    "a FMTU message marks column {k} of {:?} as its instance, which it lacks",
                    f.name
                ));
            }
        }
        for i in 0..f.columns.len() {
            let Some(k) = f.kind(i) else {
                return err(format!(
                    "message {:?} has more columns than format characters (FMTU)",
                    f.name
                ));
            };
            let scaled = matches!(k, Kind::Centi(_) | Kind::Deg7);
            let has_unit = unit_ids.get(i).is_some_and(|u| known_units.contains(u));
            if !scaled && has_unit && i >= mult_ids.len() {
                return err(format!(
                    "a FMTU message gives {:?} fewer multipliers than units",
                    f.name
                ));
            }
        }
    }
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn half_floats() {
        assert_eq!(half(0x3c00), 1.0);
        assert_eq!(half(0xc000), -2.0);
        assert_eq!(half(0x0001), 2f64.powi(-24));
        assert!(half(0x7e00).is_nan());
        assert_eq!(half(0x7c00), f64::INFINITY);
    }

    #[test]
    fn text_is_cut_at_the_first_nul_after_decoding() {
        assert_eq!(text(b"IMU\0", false), "IMU");
        assert_eq!(text(b"\xe9t\xe9\0\xff", true), "\u{e9}t\u{e9}"); // Latin-1: not UTF-8
        assert_eq!(text(b"a\xffb\0", false), "a\\xffb");
    }

    #[test]
    fn scaled_columns_divide_as_pymavlink_does() {
        let f = Format {
            name: "X".into(),
            len: 3 + 2 + 4,
            format: b"cL".to_vec(),
            columns: vec!["A".into(), "B".into()],
        };
        let mut d = Decoder::new("X", &f);
        let mut body = (-12345i16).to_le_bytes().to_vec();
        body.extend_from_slice(&473_977_441i32.to_le_bytes());
        d.push(&body, 0);
        let Column::F64(a) = &d.out.columns[0].1 else {
            panic!()
        };
        let Column::F64(b) = &d.out.columns[1].1 else {
            panic!()
        };
        assert_eq!(a[0], -12345.0 / 100.0);
        assert_eq!(b[0], 473_977_441.0 / (1.0 / 1e-7));
    }
}
