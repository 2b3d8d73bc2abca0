//! Tests of `ulog.rs` (kept apart to keep that module short).

use super::*;

#[test]
fn python_int_rules() {
    assert_eq!(py_int(" 12 "), Some(12));
    assert_eq!(py_int("1_0"), Some(10));
    assert_eq!(py_int("-0"), Some(0));
    assert_eq!(py_int("+7"), Some(7));
    for bad in ["", "_1", "1_", "1__0", "1.5", "x", "--1"] {
        assert_eq!(py_int(bad), None, "{bad}");
    }
}

#[test]
fn formats_parse_as_pyulog_parses_them() {
    let (name, f) = parse_format(b"sensor:uint64_t timestamp;float[3] x;nested n;").unwrap();
    assert_eq!(name, "sensor");
    assert_eq!(
        f,
        vec![
            ("uint64_t".into(), 0, "timestamp".into()),
            ("float".into(), 3, "x".into()),
            ("nested".into(), 0, "n".into())
        ]
    );
    assert_eq!(parse_format(b"no colon").unwrap_err(), Py::Index);
    assert_eq!(parse_format(b"a:float[70000] x;").unwrap_err(), Py::Value);
    assert_eq!(parse_format(b"a:float[x] y;").unwrap_err(), Py::Value);
    assert_eq!(parse_format(b"a:float").unwrap_err(), Py::Index);
    // no ']': Python's slice runs to the last character
    assert_eq!(parse_format(b"a:float[12 y;").unwrap().1[0].1, 1);
}

#[test]
fn info_values_unpack_as_struct_does() {
    let mut m = vec![13u8];
    m.extend_from_slice(b"uint32_t ver1");
    m.extend_from_slice(&7u32.to_le_bytes());
    assert_eq!(parse_info(&m).unwrap().2, Value::Int(7));
    m.push(0); // one byte too many: struct.error
    assert_eq!(parse_info(&m).unwrap_err(), Py::Struct);
    assert_eq!(parse_info(&[]).unwrap_err(), Py::Struct);
    assert_eq!(parse_info(b"\x03abc").unwrap_err(), Py::Index);
    let mut s = vec![10u8];
    s.extend_from_slice(b"char[3] hw\xffok");
    assert_eq!(parse_info(&s).unwrap().2, Value::Str("ok".into())); // invalid bytes dropped
}

#[test]
fn nested_formats_flatten_with_pyulog_names() {
    let mut formats = HashMap::new();
    formats.insert(
        "t".to_string(),
        parse_format(b"t:uint64_t timestamp;v[2] i;uint8_t[2] _padding0;")
            .unwrap()
            .1,
    );
    formats.insert("v".to_string(), parse_format(b"v:int16_t a;").unwrap().1);
    let mut a = vec![0u8, 5, 0];
    a.extend_from_slice(b"t");
    let s = subscription(&a, &formats).unwrap().unwrap();
    let names: Vec<&str> = s.fields.iter().map(|f| f.0.as_str()).collect();
    assert_eq!(names, ["timestamp", "i[0].a", "i[1].a"]); // trailing padding dropped
    assert_eq!((s.itemsize, s.t_off, s.msg_id), (12, 0, 5));
    formats.insert("loop".to_string(), parse_format(b"loop:loop x;").unwrap().1);
    let mut b = vec![0u8, 6, 0];
    b.extend_from_slice(b"loop");
    assert!(subscription(&b, &formats).is_err());
}
