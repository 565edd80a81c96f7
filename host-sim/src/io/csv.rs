//! Tables of numbers as CSV: one exact header line, then one row of finite numbers per
//! line. Point lists (header `x,y,z`, mm) are the common case; sweep logs
//! (`t,x,y,z,qw,qx,qy,qz`, `frame,t,u,v`, `t,row`) use the same reader and writer.

use std::path::Path;

use super::{check_points, content_lines, excerpt, parse_numbers, read_bytes, text, write_atomic};
use super::{FormatError, IoError, Location};

/// Parse a CSV table whose header is exactly `columns`, each row `N` finite numbers.
///
/// The first non-blank line must be the header (whitespace around the fields and CRLF
/// endings tolerated, as is a leading UTF-8 byte-order mark). A header with no rows gives
/// an empty table; whether that is acceptable is the caller's decision.
///
/// # Errors
///
/// [`IoError::Format`] (without a path) naming the line (counted from 1): a missing or
/// different header, a row without exactly `N` values, a value that is not a number, a
/// non-finite value.
pub fn parse_table_csv<const N: usize>(
    text: &str,
    columns: [&str; N],
) -> Result<Vec<[f64; N]>, IoError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = content_lines(text, 1);
    let header_error = |found: &str| FormatError::CsvHeader {
        expected: columns.join(","),
        found: excerpt(found),
    };
    match lines.next() {
        Some((_, header)) if header.split(',').map(str::trim).eq(columns) => {}
        Some((n, found)) => {
            return Err(IoError::format(
                header_error(found),
                Some(Location::Line(n)),
            ))
        }
        None => return Err(header_error("").into()),
    }
    lines
        .map(|(n, line)| {
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            parse_numbers(&fields).map_err(|kind| IoError::format(kind, Some(Location::Line(n))))
        })
        .collect()
}

/// Read a CSV table from `path`; see [`parse_table_csv`].
///
/// # Errors
///
/// [`IoError::Io`] if the file cannot be read; [`IoError::Format`] with the path
/// attached if it is not UTF-8 or [`parse_table_csv`] rejects it.
pub fn read_table_csv<const N: usize>(
    path: &Path,
    columns: [&str; N],
) -> Result<Vec<[f64; N]>, IoError> {
    let bytes = read_bytes(path)?;
    text(&bytes, 1)
        .and_then(|t| parse_table_csv(t, columns))
        .map_err(|e| e.with_path(path))
}

/// Write `rows` under the header `columns` (shortest round-trip number formatting),
/// atomically.
///
/// # Errors
///
/// With `path` left untouched: [`IoError::Format`] for a non-finite value (naming the
/// row); [`IoError::Io`] if the file cannot be written.
pub fn write_table_csv<const N: usize>(
    path: &Path,
    columns: [&str; N],
    rows: &[[f64; N]],
) -> Result<(), IoError> {
    if let Some(i) = rows.iter().position(|r| !r.iter().all(|v| v.is_finite())) {
        return Err(
            IoError::format(FormatError::NotFinite, Some(Location::item("row", i))).with_path(path),
        );
    }
    write_atomic(path, |out| {
        writeln!(out, "{}", columns.join(","))?;
        for r in rows {
            for (i, v) in r.iter().enumerate() {
                if i > 0 {
                    out.write_all(b",")?;
                }
                write!(out, "{v}")?;
            }
            out.write_all(b"\n")?;
        }
        Ok(())
    })
}

/// Parse a CSV point list: a table with header `x,y,z`; see [`parse_table_csv`].
///
/// # Errors
///
/// As [`parse_table_csv`].
pub fn parse_points_csv(text: &str) -> Result<Vec<[f64; 3]>, IoError> {
    parse_table_csv(text, ["x", "y", "z"])
}

/// Read a CSV point list from `path`; see [`parse_points_csv`].
///
/// # Errors
///
/// [`IoError::Io`] if the file cannot be read; [`IoError::Format`] with the path
/// attached if it is not UTF-8 or [`parse_points_csv`] rejects it.
pub fn read_points_csv(path: &Path) -> Result<Vec<[f64; 3]>, IoError> {
    read_table_csv(path, ["x", "y", "z"])
}

/// Write `points` to `path` as CSV (`x,y,z` header, shortest round-trip number
/// formatting), atomically. An empty list writes just the header.
///
/// # Errors
///
/// With `path` left untouched: [`IoError::Format`] for a non-finite coordinate
/// (naming the point); [`IoError::Io`] if the file cannot be written.
pub fn write_points_csv(path: &Path, points: &[[f64; 3]]) -> Result<(), IoError> {
    if !points.is_empty() {
        check_points(points, "point").map_err(|e| e.with_path(path))?;
    }
    write_table_csv(path, ["x", "y", "z"], points)
}

/// Split one CSV record into its fields (RFC 4180 quoting within one line).
///
/// An unquoted field is trimmed. A field whose first non-blank character is `"` is
/// quoted: it runs to the next lone `"`, `""` inside it standing for one `"`, and is kept
/// exactly (commas and spaces included); only blanks may follow it before the next comma.
/// Quoted fields spanning lines are not supported.
pub(super) fn split_record(line: &str) -> Result<Vec<String>, FormatError> {
    let mut fields = Vec::new();
    let mut rest = line;
    loop {
        let trimmed = rest.trim_start();
        if let Some(quoted) = trimmed.strip_prefix('"') {
            let mut field = String::new();
            let mut chars = quoted.char_indices().peekable();
            let after = loop {
                match chars.next() {
                    Some((_, '"')) if matches!(chars.peek(), Some((_, '"'))) => {
                        field.push('"');
                        chars.next();
                    }
                    Some((i, '"')) => break quoted.get(i + 1..).unwrap_or_default(),
                    Some((_, c)) => field.push(c),
                    None => {
                        return Err(FormatError::Syntax(
                            "quoted CSV field has no closing quote".to_owned(),
                        ))
                    }
                }
            };
            fields.push(field);
            let after = after.trim_start();
            match after.strip_prefix(',') {
                Some(next) => rest = next,
                None if after.is_empty() => return Ok(fields),
                None => {
                    return Err(FormatError::Syntax(format!(
                        "unexpected \"{}\" after a quoted CSV field",
                        excerpt(after)
                    )))
                }
            }
        } else {
            match rest.split_once(',') {
                Some((field, next)) => {
                    fields.push(field.trim().to_owned());
                    rest = next;
                }
                None => {
                    fields.push(rest.trim().to_owned());
                    return Ok(fields);
                }
            }
        }
    }
}

/// A label as one CSV field that [`split_record`] gives back exactly: quoted when it
/// holds a comma, a quote or surrounding blanks; refused when it holds a line break.
pub(super) fn quote_field(label: &str) -> Result<String, FormatError> {
    if label.contains(['\n', '\r']) {
        return Err(FormatError::UnwritableLabel(excerpt(label)));
    }
    let plain = !label.contains([',', '"']) && label.trim() == label;
    Ok(if plain {
        label.to_owned()
    } else {
        format!("\"{}\"", label.replace('"', "\"\""))
    })
}

/// Index of the column called `name` (ASCII case-insensitive) in a split header.
pub(super) fn column(header: &[String], name: &str) -> Option<usize> {
    header.iter().position(|h| h.eq_ignore_ascii_case(name))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_split_with_quotes() {
        let s = |l: &str| split_record(l).unwrap();
        assert_eq!(s("a, b ,c"), ["a", "b", "c"]);
        assert_eq!(s(""), [""]);
        assert_eq!(s("1,,2,"), ["1", "", "2", ""]);
        assert_eq!(s(r#" "a,b" , "say ""hi""",x"#), ["a,b", "say \"hi\"", "x"]);
        assert_eq!(s(r#""" , " padded ""#), ["", " padded "]);
        assert!(split_record(r#""open"#).is_err());
        assert!(split_record(r#""a"b,c"#).is_err());
        for label in ["", "plain", "a,b", "\"q\"", " pad", "é, ü", "\"\""] {
            let field = quote_field(label).unwrap();
            assert_eq!(s(&format!("1,{field},2")), ["1", label, "2"], "{label:?}");
        }
        assert_eq!(
            quote_field("two\nlines"),
            Err(FormatError::UnwritableLabel("two\nlines".to_owned()))
        );
    }

    fn message(text: &str) -> String {
        parse_points_csv(text).unwrap_err().to_string()
    }

    #[test]
    fn parses_with_crlf_blank_lines_and_spaces() {
        let text = "\u{feff}\r\n  x , y,z  \r\n1,2,3\r\n\r\n -0.5 , 1e-3,4.25\r\n\n";
        assert_eq!(
            parse_points_csv(text).unwrap(),
            vec![[1.0, 2.0, 3.0], [-0.5, 0.001, 4.25]]
        );
        assert_eq!(parse_points_csv("x,y,z\n").unwrap(), Vec::<[f64; 3]>::new());
    }

    #[test]
    fn header_errors() {
        assert_eq!(message(""), "expected header \"x,y,z\", found end of file");
        assert_eq!(
            message("\n \n"),
            "expected header \"x,y,z\", found end of file"
        );
        assert_eq!(
            message("1,2,3\n"),
            "line 1: expected header \"x,y,z\", found \"1,2,3\""
        );
        assert_eq!(
            message("\nx,y\n"),
            "line 2: expected header \"x,y,z\", found \"x,y\""
        );
        assert_eq!(
            message("X,Y,Z\n"),
            "line 1: expected header \"x,y,z\", found \"X,Y,Z\""
        );
    }

    #[test]
    fn line_errors_name_the_line() {
        let cases = [
            ("x,y,z\n1,2,3\n4,5\n", "line 3: expected 3 numbers, found 2"),
            ("x,y,z\n1,2,3,4\n", "line 2: expected 3 numbers, found 4"),
            ("x,y,z\n\n\n1;2;3\n", "line 4: expected 3 numbers, found 1"),
            ("x,y,z\n1,a,3\n", "line 2: \"a\" is not a number"),
            (
                "x,y,z\n1,,3\n",
                "line 2: empty value where a number was expected",
            ),
            ("x,y,z\n1,2,NaN\n", "line 2: coordinate is not finite"),
            (
                "x,y,z\n1,2,3\r\n-inf,2,3\r\n",
                "line 3: coordinate is not finite",
            ),
        ];
        for (text, expected) in cases {
            assert_eq!(message(text), expected, "{text:?}");
        }
    }

    #[test]
    fn round_trip_is_exact_and_atomic() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("wp.csv");
        let points = vec![[0.1, -0.0, 1.0 / 3.0], [1e-7, 123456.75, -42.0]];
        write_points_csv(&path, &points).unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            format!("x,y,z\n0.1,-0,{}\n0.0000001,123456.75,-42\n", 1.0 / 3.0)
        );
        let back = read_points_csv(&path).unwrap();
        let bits = |p: &[[f64; 3]]| p.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back), bits(&points));

        write_points_csv(&path, &[]).unwrap();
        assert_eq!(read_points_csv(&path).unwrap(), Vec::<[f64; 3]>::new());

        let e = write_points_csv(&path, &[[1.0, f64::INFINITY, 0.0]]).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!("{}: point 0: coordinate is not finite", path.display())
        );
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "x,y,z\n");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);

        let nowhere = dir.path().join("nope").join("wp.csv");
        assert!(matches!(
            write_points_csv(&nowhere, &points),
            Err(IoError::Io { .. })
        ));
        assert!(!nowhere.exists());
    }

    #[test]
    fn read_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("WP.csv");
        std::fs::write(&path, b"x,y,z\n1,2,3\n\xff\n").unwrap();
        assert_eq!(
            read_points_csv(&path).unwrap_err().to_string(),
            format!("{}: line 3: text is not valid UTF-8", path.display())
        );
        std::fs::write(&path, "x,y,z\n1,2\n").unwrap();
        assert_eq!(
            read_points_csv(&path).unwrap_err().to_string(),
            format!("{}: line 2: expected 3 numbers, found 2", path.display())
        );
        let missing = dir.path().join("none.csv");
        let e = read_points_csv(&missing).unwrap_err();
        assert_eq!(e.path(), Some(missing.as_path()));
        assert!(e.kind().is_none());
    }
}
