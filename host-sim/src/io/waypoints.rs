//! Labelled waypoints: ribreg's CSV and 3D Slicer's CSV export read here, Slicer's
//! markups JSON and legacy `.fcsv` in [`markups`](super::markups); all returned in
//! ribreg's patient frame.

use std::path::Path;

use super::csv::{column, quote_field, split_record};
use super::{check_points, content_lines, excerpt, markups, parse_coordinate, read_bytes, text};
use super::{write_atomic, FormatError, IoError, Location, Space};

/// Waypoints with their labels.
///
/// `points` are **always in ribreg's patient frame** (mm; x left, y cranial, z
/// anterior; see [`space`](super::space)), whatever system the file was in.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Waypoints {
    /// The waypoints, in file order, in the patient frame.
    pub points: Vec<[f64; 3]>,
    /// One label per point (empty strings when the file has none). A writer also
    /// accepts an empty vector for "no labels".
    pub labels: Vec<String>,
    /// Written only: one flag per point, whether the sweep reaches it (`register
    /// --partial`); empty for "not marked" (every file read has it empty).
    pub supported: Vec<bool>,
}

/// The waypoint formats, from the file name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Csv,
    MarkupsJson,
    Fcsv,
}

/// The extensions accepted, for messages.
const EXPECTED: &str = ".csv, .fcsv or .mrk.json";

fn format_of(path: &Path) -> Result<Format, IoError> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let extension = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match extension.as_str() {
        "csv" => Ok(Format::Csv),
        "fcsv" => Ok(Format::Fcsv),
        "json" if name.ends_with(".mrk.json") => Ok(Format::MarkupsJson),
        _ => {
            let extension = if extension == "json" {
                "json (only .mrk.json is a markups file)".to_owned()
            } else {
                extension
            };
            Err(IoError::from(FormatError::UnknownFileExtension {
                what: "waypoint",
                extension,
                expected: EXPECTED,
            })
            .with_path(path))
        }
    }
}

/// Read waypoints from `path`, choosing the format by extension (case-insensitive),
/// and convert them to ribreg's patient frame:
///
/// - `.csv`: [`parse_waypoints_csv`]: ribreg's own `x,y,z[,label]` (patient frame) or
///   3D Slicer's markups CSV export (`label,l,p,s,...` or `label,r,a,s,...`);
/// - `.mrk.json`: 3D Slicer Markups JSON, [`parse_markups_json`](super::parse_markups_json);
/// - `.fcsv`: legacy Slicer fiducials, [`parse_fcsv`](super::parse_fcsv).
///
/// # Errors
///
/// All with the path attached: [`IoError::Io`] if the file cannot be read;
/// [`IoError::Format`] for an unknown extension, text that is not UTF-8, or whatever
/// the format's parser rejects (no waypoints is always an error,
/// [`FormatError::NoWaypoints`]).
pub fn read_waypoints(path: &Path) -> Result<Waypoints, IoError> {
    let format = format_of(path)?;
    let bytes = read_bytes(path)?;
    text(&bytes, 1)
        .and_then(|t| {
            let t = t.strip_prefix('\u{feff}').unwrap_or(t);
            match format {
                Format::Csv => parse_waypoints_csv(t),
                Format::MarkupsJson => markups::parse_markups_json(t),
                Format::Fcsv => markups::parse_fcsv(t),
            }
        })
        .map_err(|e| e.with_path(path))
}

/// Write `waypoints` (patient frame) to `path`, choosing the format by extension,
/// atomically:
///
/// - `.csv`: header `x,y,z` (patient frame, shortest round-trip numbers), or
///   `x,y,z,label` when any label is non-empty; labels holding commas, quotes or
///   surrounding blanks are quoted (RFC 4180), as [`parse_waypoints_csv`] reads them.
///   With [`Waypoints::supported`], a last column `supported` (`true` / `false`).
/// - `.mrk.json`: a 3D Slicer Markups JSON file (schema v1.0.3) holding one `Fiducial`
///   markup in LPS, mm, control points with ids `1`..`N`, all `defined`; one marked not
///   supported has the description `not reached by the sweep: do not drive here`.
///
/// Reading the file back gives the same points (to rounding of the frame conversion,
/// which only swaps and negates, so exactly) and labels.
///
/// # Errors
///
/// With `path` left untouched: [`IoError::Format`] for an unknown extension (`.fcsv`
/// is read only), no waypoints ([`FormatError::NoWaypoints`]), a non-finite coordinate
/// (naming the point), a label count other than zero or the point count, a label with
/// a line break (CSV); [`IoError::Io`] if the file cannot be written.
pub fn write_waypoints(path: &Path, waypoints: &Waypoints) -> Result<(), IoError> {
    let checked = (|| {
        let format = match format_of(path)? {
            Format::Fcsv => {
                return Err(FormatError::UnknownFileExtension {
                    what: "waypoint output",
                    extension: "fcsv".to_owned(),
                    expected: ".csv or .mrk.json",
                }
                .into())
            }
            f => f,
        };
        let points = &waypoints.points;
        if points.is_empty() {
            return Err(FormatError::NoWaypoints.into());
        }
        check_points(points, "waypoint")?;
        let labels = &waypoints.labels;
        if !labels.is_empty() && labels.len() != points.len() {
            return Err(FormatError::LabelCountMismatch {
                labels: labels.len(),
                points: points.len(),
            }
            .into());
        }
        let flags = waypoints.supported.len();
        if flags != 0 && flags != points.len() {
            return Err(FormatError::LabelCountMismatch {
                labels: flags,
                points: points.len(),
            }
            .into());
        }
        Ok(format)
    })();
    let format = checked.map_err(|e: IoError| e.with_path(path))?;
    let label = |i: usize| waypoints.labels.get(i).map_or("", String::as_str);
    let supported = |i: usize| waypoints.supported.get(i).copied();
    match format {
        Format::MarkupsJson => {
            let json = markups::to_markups_json(&waypoints.points, label, supported);
            write_atomic(path, |out| out.write_all(json.as_bytes()))
        }
        _ => {
            let with_labels = waypoints.labels.iter().any(|l| !l.is_empty());
            let mut rows = Vec::with_capacity(waypoints.points.len());
            for (i, p) in waypoints.points.iter().enumerate() {
                let mut row = format!("{},{},{}", p[0], p[1], p[2]);
                if with_labels {
                    let field = quote_field(label(i)).map_err(|kind| {
                        IoError::format(kind, Some(Location::item("waypoint", i))).with_path(path)
                    })?;
                    row.push(',');
                    row.push_str(&field);
                }
                if let Some(s) = supported(i) {
                    row.push_str(if s { ",true" } else { ",false" });
                }
                rows.push(row);
            }
            let mut header = String::from(if with_labels { "x,y,z,label" } else { "x,y,z" });
            if !waypoints.supported.is_empty() {
                header.push_str(",supported");
            }
            write_atomic(path, |out| {
                writeln!(out, "{header}")?;
                for row in &rows {
                    writeln!(out, "{row}")?;
                }
                Ok(())
            })
        }
    }
}

/// Parse a CSV waypoint list, the columns found by name (ASCII case-insensitive, in
/// any order, other columns allowed and ignored):
///
/// - `x`, `y`, `z`: ribreg's own file, already in the patient frame;
/// - else `l`, `p`, `s`: 3D Slicer's markups CSV export in LPS
///   (`label,l,p,s,defined,selected,visible,locked,description`);
/// - else `r`, `a`, `s`: the same export in RAS.
///
/// A `label` column is kept (empty labels otherwise). When a `defined` column is
/// present, rows whose value is `0` or `false` (points not placed yet) are skipped,
/// as the JSON reader skips undefined control points. Fields may be quoted (RFC 4180,
/// one line per record); blank lines are skipped.
///
/// # Errors
///
/// [`IoError::Format`] (without a path), naming the line: no header, or one with none of
/// the coordinate column sets ([`FormatError::CsvColumns`]); a row with the wrong number
/// of fields; a coordinate that is not a finite number; no (defined) rows
/// ([`FormatError::NoWaypoints`]).
pub fn parse_waypoints_csv(text: &str) -> Result<Waypoints, IoError> {
    let mut lines = content_lines(text, 1);
    let at = |n| move |kind| IoError::format(kind, Some(Location::Line(n)));
    let (n, header_line) = lines.next().ok_or(FormatError::NoWaypoints)?;
    let header = split_record(header_line).map_err(at(n))?;
    let find = |names: [&str; 3]| {
        let [a, b, c] = names.map(|name| column(&header, name));
        Some([a?, b?, c?])
    };
    let (columns, space) = match (
        find(["x", "y", "z"]),
        find(["l", "p", "s"]),
        find(["r", "a", "s"]),
    ) {
        (Some(c), _, _) => (c, Space::Patient),
        (None, Some(c), _) => (c, Space::Lps),
        (None, None, Some(c)) => (c, Space::Ras),
        (None, None, None) => {
            return Err(at(n)(FormatError::CsvColumns {
                expected: "x,y,z (patient frame), l,p,s (LPS) or r,a,s (RAS)",
                found: excerpt(header_line),
            }))
        }
    };
    let label = column(&header, "label");
    let defined = column(&header, "defined");
    let mut out = Waypoints::default();
    for (n, line) in lines {
        let fields = split_record(line).map_err(at(n))?;
        if fields.len() != header.len() {
            return Err(at(n)(FormatError::TokenCount {
                expected: header.len(),
                found: fields.len(),
            }));
        }
        if let Some(d) = defined {
            let value = fields[d].to_ascii_lowercase();
            if value == "0" || value == "false" {
                continue;
            }
        }
        push_row(&mut out, &fields, columns, label, space).map_err(at(n))?;
    }
    nonempty(out)
}

/// The waypoint of one table row (`xyz` and `label` its columns, in `space`) onto `out`
/// (the CSV and `.fcsv` readers' shared step).
pub(super) fn push_row(
    out: &mut Waypoints,
    fields: &[String],
    xyz: [usize; 3],
    label: Option<usize>,
    space: Space,
) -> Result<(), FormatError> {
    let mut p = [0.0; 3];
    for (c, &i) in p.iter_mut().zip(&xyz) {
        *c = parse_coordinate(fields.get(i).map_or("", String::as_str))?;
    }
    out.points.push(space.to_patient(p));
    out.labels.push(
        label
            .and_then(|i| fields.get(i).cloned())
            .unwrap_or_default(),
    );
    Ok(())
}

/// `out`, or [`FormatError::NoWaypoints`] when it holds none.
pub(super) fn nonempty(out: Waypoints) -> Result<Waypoints, IoError> {
    if out.points.is_empty() {
        return Err(FormatError::NoWaypoints.into());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> String {
        parse_waypoints_csv(text).unwrap_err().to_string()
    }

    #[test]
    fn csv_in_three_frames() {
        let own = parse_waypoints_csv("x,y,z\n1,2,3\n").unwrap();
        assert_eq!(own.points, vec![[1.0, 2.0, 3.0]]);
        assert_eq!(own.labels, vec![String::new()]);
        let lps = parse_waypoints_csv(
            "label,l,p,s,defined,selected,visible,locked,description\n\
             \"F-1, tip\",10,-20,30,1,1,1,0,\"a \"\"quoted\"\" note\"\n\
             F-2,0,0,0,0,1,1,0,\n",
        )
        .unwrap();
        assert_eq!(lps.points, vec![[10.0, 30.0, 20.0]]);
        assert_eq!(lps.labels, vec!["F-1, tip".to_owned()]);
        let ras = parse_waypoints_csv("Label,R,A,S\nP,10,20,30\n").unwrap();
        assert_eq!(ras.points, vec![[-10.0, 30.0, 20.0]]);
        assert_eq!(ras.labels, vec!["P".to_owned()]);
        // ribreg's columns win over Slicer's if a file has both.
        let both = parse_waypoints_csv("id,x,y,z,l,p,s,label\n7,1,2,3,4,5,6,n\n").unwrap();
        assert_eq!(both.points, vec![[1.0, 2.0, 3.0]]);
    }

    #[test]
    fn csv_errors() {
        assert_eq!(err(""), "no waypoints");
        assert_eq!(err("x,y,z\n"), "no waypoints");
        assert_eq!(err("label,l,p,s,defined\nA,1,2,3,false\n"), "no waypoints");
        assert_eq!(
            err("label,l,p\nA,1,2\n"),
            "line 1: CSV header needs columns x,y,z (patient frame), l,p,s (LPS) \
             or r,a,s (RAS), found \"label,l,p\""
        );
        assert_eq!(err("x,y,z\n1,2\n"), "line 2: expected 3 numbers, found 2");
        assert_eq!(err("x,y,z\n1,2,inf\n"), "line 2: coordinate is not finite");
        assert_eq!(err("l,p,s\n1,b,3\n"), "line 2: \"b\" is not a number");
    }

    fn sample() -> Waypoints {
        Waypoints {
            points: vec![
                [0.1, -0.0, 1.0 / 3.0],
                [1e-7, 123456.75, -42.0],
                [5.0, 6.0, 7.0],
            ],
            labels: vec![
                "tip, left".to_owned(),
                "say \"hi\"".to_owned(),
                String::new(),
            ],
            supported: vec![],
        }
    }

    #[test]
    fn round_trips_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let bits = |w: &Waypoints| {
            w.points
                .iter()
                .flatten()
                .map(|v| (v + 0.0).to_bits())
                .collect::<Vec<_>>()
        };
        for name in ["w.csv", "w.mrk.json", "W.MRK.JSON"] {
            let path = dir.path().join(name);
            write_waypoints(&path, &sample()).unwrap();
            let back = read_waypoints(&path).unwrap();
            assert_eq!(bits(&back), bits(&sample()), "{name}");
            assert_eq!(back.labels, sample().labels, "{name}");
            let unlabelled = Waypoints {
                labels: vec![],
                ..sample()
            };
            write_waypoints(&path, &unlabelled).unwrap();
            let back = read_waypoints(&path).unwrap();
            assert_eq!(bits(&back), bits(&sample()), "{name}");
            assert_eq!(back.labels, vec![String::new(); 3], "{name}");
        }
        let csv = dir.path().join("w.csv");
        write_waypoints(&csv, &sample()).unwrap();
        assert!(std::fs::read_to_string(&csv)
            .unwrap()
            .starts_with("x,y,z,label\n0.1,-0,"));
    }

    /// `register --partial`'s flags: a last `supported` column, which the reader skips
    /// like any other column; a flag count other than the points' is refused.
    #[test]
    fn supported_flags_are_a_last_column() {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("w.csv");
        let marked = Waypoints {
            supported: vec![true, false, true],
            ..sample()
        };
        write_waypoints(&csv, &marked).unwrap();
        let text = std::fs::read_to_string(&csv).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "x,y,z,label,supported");
        assert!(lines[1].ends_with(",\"tip, left\",true"), "{}", lines[1]);
        assert!(lines[2].ends_with(",false"), "{}", lines[2]);
        assert_eq!(read_waypoints(&csv).unwrap().points, sample().points);
        let unlabelled = Waypoints {
            labels: vec![],
            ..marked.clone()
        };
        write_waypoints(&csv, &unlabelled).unwrap();
        let text = std::fs::read_to_string(&csv).unwrap();
        assert!(text.starts_with("x,y,z,supported\n"), "{text}");
        let short = Waypoints {
            supported: vec![true],
            ..sample()
        };
        let other = dir.path().join("o.csv");
        assert!(write_waypoints(&other, &short).is_err());
        assert!(!other.exists());
    }

    #[test]
    fn writer_refusals_leave_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("w.csv");
        let e = |path: &Path, w: &Waypoints| write_waypoints(path, w).unwrap_err().to_string();
        let d = csv.display();
        assert_eq!(e(&csv, &Waypoints::default()), format!("{d}: no waypoints"));
        let mut nan = sample();
        nan.points[1][2] = f64::NAN;
        assert_eq!(
            e(&csv, &nan),
            format!("{d}: waypoint 1: coordinate is not finite")
        );
        let mut short = sample();
        short.labels.pop();
        assert_eq!(e(&csv, &short), format!("{d}: 2 labels for 3 points"));
        let mut newline = sample();
        newline.labels[2] = "a\nb".to_owned();
        assert_eq!(
            e(&csv, &newline),
            format!("{d}: waypoint 2: label \"a\nb\" holds a line break and cannot be written")
        );
        let fcsv = dir.path().join("w.fcsv");
        assert!(e(&fcsv, &sample()).contains("unknown waypoint output file extension \"fcsv\""));
        let json = dir.path().join("w.json");
        assert_eq!(
            e(&json, &sample()),
            format!(
                "{}: unknown waypoint file extension \"json (only .mrk.json is a markups file)\" \
                 (expected .csv, .fcsv or .mrk.json)",
                json.display()
            )
        );
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        let missing = dir.path().join("none.csv");
        assert!(matches!(read_waypoints(&missing), Err(IoError::Io { .. })));
    }
}
