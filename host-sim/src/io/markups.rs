//! 3D Slicer markups: Markups JSON (`.mrk.json`, schema v1.0.3) and legacy fiducial
//! lists (`.fcsv`), read into ribreg's patient frame; Markups JSON written.

use serde_json::{json, Value};

use super::csv::split_record;
use super::Waypoints;
use super::{content_lines, excerpt, FormatError, IoError, Location, Space};

/// The schema a written Markups JSON file names.
const SCHEMA: &str = "https://raw.githubusercontent.com/slicer/slicer/master/Modules/\
                      Loadable/Markups/Resources/Schema/markups-schema-v1.0.3.json#";

/// The coordinate system a markups file names: RAS or LPS (any case). `patient` and
/// Slicer's numeric codes are not accepted here; legacy `.fcsv` handles its codes itself.
fn ras_or_lps(name: &str) -> Result<Space, FormatError> {
    match name.trim().to_ascii_uppercase().as_str() {
        "RAS" => Ok(Space::Ras),
        "LPS" => Ok(Space::Lps),
        _ => Err(FormatError::UnknownSpace(excerpt(name))),
    }
}

/// Parse a 3D Slicer Markups JSON file (`.mrk.json`): every control point of every
/// markup in `markups[]` (fiducials, but also the points of lines, curves, planes...),
/// in file order, converted to ribreg's patient frame.
///
/// Per markup: `coordinateSystem` is `LPS` (the default when absent, as in Slicer) or
/// `RAS`; `coordinateUnits` must be `mm` (or the code triple `["mm", "UCUM", ...]`) or
/// absent, `um` and anything else being refused. Per control point: `position` (three
/// numbers) is required; `label` is kept (empty when absent); `positionStatus`
/// `defined` (or absent) is kept, while `undefined` and `preview` points (placeholders
/// not placed yet, or a point being placed) are **skipped**, so the result holds only
/// the points the user placed. Other keys (`orientation`, `display`, `measurements`...)
/// are ignored.
///
/// # Errors
///
/// [`IoError::Format`] (without a path): not JSON, no `markups` array, or a malformed
/// markup or control point ([`FormatError::Markups`], naming `markup M` or `markup M
/// control point C`); an unknown coordinate system ([`FormatError::UnknownSpace`]) or
/// units ([`FormatError::UnknownUnits`]); a position too large to be finite; no defined
/// control point at all ([`FormatError::NoWaypoints`]).
pub fn parse_markups_json(text: &str) -> Result<Waypoints, IoError> {
    let bad = |s: String| IoError::from(FormatError::Markups(s));
    let root: Value = serde_json::from_str(text).map_err(|e| bad(format!("not JSON: {e}")))?;
    let markups = root
        .get("markups")
        .and_then(Value::as_array)
        .ok_or_else(|| bad("no \"markups\" array".to_owned()))?;
    let mut out = Waypoints::default();
    for (m, markup) in markups.iter().enumerate() {
        let at_markup = |kind| IoError::format(kind, Some(Location::item("markup", m)));
        let text_key = |key: &str| match markup.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(Value::String(s)) => Ok(Some(s.as_str())),
            Some(_) => Err(at_markup(FormatError::Markups(format!(
                "\"{key}\" is not a string"
            )))),
        };
        let space = match text_key("coordinateSystem")? {
            None => Space::Lps,
            Some(name) => ras_or_lps(name).map_err(at_markup)?,
        };
        // A UCUM code, or (schema v1.0.3) a DICOM-style [code, scheme, meaning] triple.
        let units = match markup.get("coordinateUnits") {
            Some(Value::Array(code)) => match code.first() {
                Some(Value::String(s)) => Some(s.as_str()),
                _ => {
                    return Err(at_markup(FormatError::Markups(
                        "\"coordinateUnits\" is not a unit code".to_owned(),
                    )))
                }
            },
            _ => text_key("coordinateUnits")?,
        };
        match units {
            None | Some("mm") => {}
            Some(units) => return Err(at_markup(FormatError::UnknownUnits(excerpt(units)))),
        }
        let points = match markup.get("controlPoints") {
            None | Some(Value::Null) => continue,
            Some(Value::Array(points)) => points,
            Some(_) => {
                return Err(at_markup(FormatError::Markups(
                    "\"controlPoints\" is not an array".to_owned(),
                )))
            }
        };
        for (c, point) in points.iter().enumerate() {
            let at = |problem: &str| {
                IoError::format(
                    FormatError::Markups(problem.to_owned()),
                    Some(Location::Item {
                        element: format!("markup {m} control point"),
                        index: c,
                    }),
                )
            };
            if !point.is_object() {
                return Err(at("not an object"));
            }
            match point.get("positionStatus") {
                None | Some(Value::Null) => {}
                Some(Value::String(s)) if s == "defined" => {}
                Some(Value::String(s)) if s == "undefined" || s == "preview" => continue,
                Some(_) => {
                    return Err(at(
                        "positionStatus is not \"defined\", \"undefined\" or \"preview\"",
                    ))
                }
            }
            let position = match point.get("position") {
                None | Some(Value::Null) => return Err(at("no position")),
                Some(Value::Array(p)) => p,
                Some(_) => return Err(at("position is not an array")),
            };
            let p: Vec<f64> = position.iter().filter_map(Value::as_f64).collect();
            let p: [f64; 3] = match p.try_into() {
                Ok(p) if position.len() == 3 => p,
                _ => return Err(at("position is not three numbers")),
            };
            if !p.iter().all(|v| v.is_finite()) {
                return Err(at("position is not finite"));
            }
            let label = match point.get("label") {
                None | Some(Value::Null) => String::new(),
                Some(Value::String(s)) => s.clone(),
                Some(_) => return Err(at("label is not a string")),
            };
            out.points.push(space.to_patient(p));
            out.labels.push(label);
        }
    }
    if out.points.is_empty() {
        return Err(FormatError::NoWaypoints.into());
    }
    Ok(out)
}

/// The columns of a legacy fiducial file when it has no `# columns =` line (Slicer 4.x).
const FCSV_COLUMNS: &str = "id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID";

/// Parse a legacy 3D Slicer fiducial list (`.fcsv`, "Markups fiducial file version =
/// 4.x") into ribreg's patient frame.
///
/// Header comment lines: `# CoordinateSystem = RAS`, `LPS`, `0` (RAS) or `1` (LPS).
/// **A file without a `CoordinateSystem` line is taken as RAS**, the system Slicer
/// wrote before it started to declare one (Slicer ≥ 4.11 writes `LPS` and says so).
/// `# columns = ...` names the columns (the default is Slicer 4's
/// `id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID`); `x`, `y`, `z` are
/// required and `label` is kept. Other comment lines are ignored. Every data row is a
/// waypoint (the `vis`/`sel`/`lock` flags do not drop points); fields may be quoted.
///
/// # Errors
///
/// [`IoError::Format`] (without a path), naming the line: an unknown coordinate system
/// ([`FormatError::UnknownSpace`]); a `columns` line without x, y and z
/// ([`FormatError::CsvColumns`]); a row whose field count differs from the columns; a
/// coordinate that is not a finite number; no rows ([`FormatError::NoWaypoints`]).
pub fn parse_fcsv(text: &str) -> Result<Waypoints, IoError> {
    let mut space = Space::Ras;
    let mut columns: Vec<String> = FCSV_COLUMNS.split(',').map(str::to_owned).collect();
    let mut out = Waypoints::default();
    // x, y, z and label in FCSV_COLUMNS.
    let mut layout = ([1, 2, 3], Some(11));
    for (n, line) in content_lines(text, 1) {
        let at = |kind| IoError::format(kind, Some(Location::Line(n)));
        if let Some(comment) = line.strip_prefix('#') {
            let Some((key, value)) = comment.split_once('=') else {
                continue;
            };
            match key.trim().to_ascii_lowercase().as_str() {
                "coordinatesystem" => {
                    space = match value.trim() {
                        "0" => Space::Ras,
                        "1" => Space::Lps,
                        name => ras_or_lps(name).map_err(at)?,
                    }
                }
                "columns" => {
                    columns = split_record(value).map_err(at)?;
                    layout = fcsv_layout(&columns).ok_or_else(|| {
                        at(FormatError::CsvColumns {
                            expected: "x, y and z",
                            found: excerpt(value.trim()),
                        })
                    })?;
                }
                _ => {}
            }
            continue;
        }
        let fields = split_record(line).map_err(at)?;
        if fields.len() != columns.len() {
            return Err(at(FormatError::TokenCount {
                expected: columns.len(),
                found: fields.len(),
            }));
        }
        let (xyz, label) = layout;
        super::waypoints::push_row(&mut out, &fields, xyz, label, space).map_err(at)?;
    }
    super::waypoints::nonempty(out)
}

/// Indices of x, y, z and the optional label among fcsv `columns`.
fn fcsv_layout(columns: &[String]) -> Option<([usize; 3], Option<usize>)> {
    let find = |name: &str| super::csv::column(columns, name);
    Some(([find("x")?, find("y")?, find("z")?], find("label")))
}

/// A Markups JSON document holding `points` (patient frame) as one `Fiducial` markup in
/// LPS, mm, ids `1`..`N`, all `defined`, with `label(i)` for point `i`.
pub(super) fn to_markups_json<'a>(
    points: &[[f64; 3]],
    label: impl Fn(usize) -> &'a str,
    supported: impl Fn(usize) -> Option<bool>,
) -> String {
    let control_points: Vec<Value> = points
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            let mut point = json!({
                "id": (i + 1).to_string(),
                "label": label(i),
                "position": Space::Lps.from_patient(p),
                "positionStatus": "defined",
            });
            if supported(i) == Some(false) {
                point["description"] = json!(NOT_REACHED);
            }
            point
        })
        .collect();
    let document = json!({
        "@schema": SCHEMA,
        "markups": [{
            "type": "Fiducial",
            "coordinateSystem": "LPS",
            "coordinateUnits": "mm",
            "controlPoints": control_points,
        }],
    });
    let mut text = document.to_string();
    if let Ok(pretty) = serde_json::to_string_pretty(&document) {
        text = pretty;
    }
    text.push('\n');
    text
}

/// The description of a control point the sweep does not reach (`register --partial`).
pub const NOT_REACHED: &str = "not reached by the sweep: do not drive here";

#[cfg(test)]
mod tests {
    use super::*;

    fn json_err(text: &str) -> String {
        parse_markups_json(text).unwrap_err().to_string()
    }

    const LPS: &str = r#"{"@schema": "x", "markups": [
        {"type": "Fiducial", "coordinateSystem": "LPS", "coordinateUnits": "mm",
         "controlPoints": [
            {"id": "1", "label": "F-1", "position": [10.0, -20.0, 30.0], "positionStatus": "defined"},
            {"id": "2", "label": "F-2", "position": [0, 0, 0], "positionStatus": "undefined"},
            {"id": "3", "position": [1, 2, 3], "positionStatus": "preview"},
            {"id": "4", "label": "F-4", "position": [1, 2, 3]}
         ]},
        {"type": "Curve", "coordinateSystem": "RAS", "controlPoints": [
            {"label": "C", "position": [10, 20, 30]}
        ]},
        {"type": "Line", "controlPoints": [{"label": "D", "position": [1, 0, 0]}]},
        {"type": "Plane"}
    ]}"#;

    #[test]
    fn json_points_in_the_patient_frame() {
        let w = parse_markups_json(LPS).unwrap();
        assert_eq!(
            w.points,
            vec![
                [10.0, 30.0, 20.0],
                [1.0, 3.0, -2.0],
                [-10.0, 30.0, 20.0],
                [1.0, 0.0, -0.0]
            ]
        );
        assert_eq!(w.labels, ["F-1", "F-4", "C", "D"]);
    }

    #[test]
    fn json_errors() {
        let cp = |point: &str| {
            json_err(&format!(
                r#"{{"markups": [{{"controlPoints": [{{"position": [1, 2, 3]}}, {point}]}}]}}"#
            ))
        };
        assert!(json_err("").starts_with("bad markups file: not JSON: "));
        assert!(json_err("{\"markups\": [").starts_with("bad markups file: not JSON: "));
        assert_eq!(json_err("{}"), "bad markups file: no \"markups\" array");
        assert_eq!(json_err(r#"{"markups": []}"#), "no waypoints");
        assert_eq!(
            json_err(
                r#"{"markups": [{"controlPoints": [{"position": [1,2,3], "positionStatus": "undefined"}]}]}"#
            ),
            "no waypoints"
        );
        assert_eq!(
            json_err(r#"{"markups": [{"coordinateSystem": "IJK", "controlPoints": []}]}"#),
            "markup 0: unknown coordinate system \"IJK\" (expected RAS or LPS)"
        );
        assert_eq!(
            json_err(r#"{"markups": [{}, {"coordinateSystem": 0}]}"#),
            "markup 1: bad markups file: \"coordinateSystem\" is not a string"
        );
        assert_eq!(
            json_err(r#"{"markups": [{"coordinateUnits": "um", "controlPoints": []}]}"#),
            "markup 0: unsupported coordinate units \"um\" (expected mm)"
        );
        assert_eq!(
            json_err(r#"{"markups": [{"coordinateUnits": ["um", "UCUM", "micrometer"]}]}"#),
            "markup 0: unsupported coordinate units \"um\" (expected mm)"
        );
        assert_eq!(
            json_err(r#"{"markups": [{"coordinateUnits": [1]}]}"#),
            "markup 0: bad markups file: \"coordinateUnits\" is not a unit code"
        );
        let triple = r#"{"markups": [{"coordinateUnits": ["mm", "UCUM", "millimeter"],
            "controlPoints": [{"position": [1, 2, 3]}]}]}"#;
        assert_eq!(parse_markups_json(triple).unwrap().points.len(), 1);
        assert_eq!(
            json_err(r#"{"markups": [{"controlPoints": {}}]}"#),
            "markup 0: bad markups file: \"controlPoints\" is not an array"
        );
        assert_eq!(
            cp(r#"{"label": "x"}"#),
            "markup 0 control point 1: bad markups file: no position"
        );
        assert_eq!(
            cp(r#"{"position": [1, 2]}"#),
            "markup 0 control point 1: bad markups file: position is not three numbers"
        );
        assert_eq!(
            cp(r#"{"position": [1, "2", 3]}"#),
            "markup 0 control point 1: bad markups file: position is not three numbers"
        );
        assert_eq!(
            cp(r#"{"position": "1 2 3"}"#),
            "markup 0 control point 1: bad markups file: position is not an array"
        );
        assert_eq!(
            cp(r#"{"position": [1, 2, 3], "positionStatus": "maybe"}"#),
            "markup 0 control point 1: bad markups file: \
             positionStatus is not \"defined\", \"undefined\" or \"preview\""
        );
        assert_eq!(
            cp(r#"{"position": [1, 2, 3], "label": 5}"#),
            "markup 0 control point 1: bad markups file: label is not a string"
        );
        assert_eq!(
            cp("7"),
            "markup 0 control point 1: bad markups file: not an object"
        );
        assert!(cp(r#"{"position": [1, 2, 1e999]}"#).starts_with("bad markups file: not JSON"));
    }

    const FCSV: &str = "# Markups fiducial file version = 4.11\n# CoordinateSystem = LPS\n\
        # columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n\
        vtkMRMLMarkupsFiducialNode_0,10,-20,30,0,0,0,1,1,1,0,F-1,,vtkMRMLScalarVolumeNode1\n\
        vtkMRMLMarkupsFiducialNode_1,1,2,3,0,0,0,1,0,1,1,\"a, b\",\"note, with comma\",\n";

    #[test]
    fn fcsv_systems() {
        let w = parse_fcsv(FCSV).unwrap();
        assert_eq!(w.points, vec![[10.0, 30.0, 20.0], [1.0, 3.0, -2.0]]);
        assert_eq!(w.labels, ["F-1", "a, b"]);
        for (line, space) in [
            ("# CoordinateSystem = 1", Space::Lps),
            ("# CoordinateSystem = 0", Space::Ras),
            ("# CoordinateSystem = RAS", Space::Ras),
            ("# nothing declared", Space::Ras),
        ] {
            let text = FCSV.replace("# CoordinateSystem = LPS", line);
            let w = parse_fcsv(&text).unwrap();
            assert_eq!(w.points[0], space.to_patient([10.0, -20.0, 30.0]), "{line}");
        }
        // Without a columns line, Slicer 4's default order.
        let bare = "# CoordinateSystem = 0\nid1,1,2,3,0,0,0,1,1,1,0,L,,\n";
        let w = parse_fcsv(bare).unwrap();
        assert_eq!(w.points, vec![[-1.0, 3.0, 2.0]]);
        assert_eq!(w.labels, ["L"]);
        // A reordered columns line is honoured.
        let custom = "# columns = label,z,y,x\nA,3,2,1\n";
        assert_eq!(parse_fcsv(custom).unwrap().points, vec![[-1.0, 3.0, 2.0]]);
    }

    #[test]
    fn fcsv_errors() {
        let err = |t: &str| parse_fcsv(t).unwrap_err().to_string();
        assert_eq!(
            err("# CoordinateSystem = 2\n"),
            "line 1: unknown coordinate system \"2\" (expected RAS or LPS)"
        );
        assert_eq!(
            err(&FCSV.replace("= LPS", "= patient")),
            "line 2: unknown coordinate system \"patient\" (expected RAS or LPS)"
        );
        assert_eq!(
            err("# columns = id,x,y,label\n"),
            "line 1: CSV header needs columns x, y and z, found \"id,x,y,label\""
        );
        assert_eq!(
            err("# columns = x,y,z\n1,2\n"),
            "line 2: expected 3 numbers, found 2"
        );
        assert_eq!(
            err("# columns = x,y,z\n1,2,nan\n"),
            "line 2: coordinate is not finite"
        );
        assert_eq!(err(""), "no waypoints");
        assert_eq!(
            err("# Markups fiducial file version = 4.11\n# CoordinateSystem = LPS\n"),
            "no waypoints"
        );
    }

    #[test]
    fn written_json_reads_back_and_names_lps() {
        let points = [[1.0, 2.0, 3.0], [-4.5, 0.25, 1e-9]];
        let labels = ["a", "b \"q\""];
        let text = to_markups_json(&points, |i| labels[i], |i| Some(i == 0));
        let v: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["@schema"], SCHEMA);
        let m = &v["markups"][0];
        assert_eq!(m["type"], "Fiducial");
        assert_eq!(m["coordinateSystem"], "LPS");
        assert_eq!(m["coordinateUnits"], "mm");
        assert_eq!(m["controlPoints"][1]["id"], "2");
        assert_eq!(m["controlPoints"][0]["position"], json!([1.0, -3.0, 2.0]));
        assert_eq!(m["controlPoints"][0]["positionStatus"], "defined");
        // Marked not supported: a description; supported: none.
        assert!(m["controlPoints"][0].get("description").is_none());
        assert_eq!(m["controlPoints"][1]["description"], NOT_REACHED);
        let back = parse_markups_json(&text).unwrap();
        assert_eq!(back.points, points);
        assert_eq!(back.labels, labels);
    }
}
