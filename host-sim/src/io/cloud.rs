//! Point clouds by extension ([`read_cloud`]) and CSV clouds with named columns.

use std::path::Path;

use super::csv::{column, split_record};
use super::{content_lines, excerpt, parse_coordinate, read_bytes, text};
use super::{pcd, ply, xyz, Cloud, FormatError, IoError, Location};

/// Read a point cloud from `path`, choosing the format by extension (case-insensitive):
///
/// - `.ply`: [`read_ply`](super::read_ply);
/// - `.pcd`: [`parse_pcd`](super::parse_pcd) (ascii, binary, binary_compressed);
/// - `.xyz`, `.xyzn`, `.xyzrgb`: [`parse_xyz`](super::parse_xyz) (Open3D's text clouds);
/// - `.csv`, `.txt`: [`parse_cloud_csv`] (a header naming `x`, `y`, `z`, optional `label`).
///
/// Coordinates are taken as they are (mm, no frame conversion: none of these formats
/// declares a coordinate system).
///
/// # Errors
///
/// All with the path attached: [`IoError::Io`] if the file cannot be read;
/// [`IoError::Format`] for an unknown extension
/// ([`FormatError::UnknownFileExtension`]) or whatever the format's parser rejects.
pub fn read_cloud(path: &Path) -> Result<Cloud, IoError> {
    let extension = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let parse: fn(&[u8]) -> Result<Cloud, IoError> = match extension.as_str() {
        "ply" => ply::parse_ply,
        "pcd" => pcd::parse_pcd,
        "xyz" | "xyzn" | "xyzrgb" => |bytes| xyz::parse_xyz(text(bytes, 1)?),
        "csv" | "txt" => |bytes| parse_cloud_csv(text(bytes, 1)?),
        _ => {
            let kind = FormatError::UnknownFileExtension {
                what: "point cloud",
                extension,
                expected: ".ply, .pcd, .xyz, .xyzn, .xyzrgb, .csv or .txt",
            };
            return Err(IoError::from(kind).with_path(path));
        }
    };
    parse(&read_bytes(path)?).map_err(|e| e.with_path(path))
}

/// Parse a CSV point cloud whose header names the columns: `x`, `y` and `z` (any
/// order, ASCII case-insensitive) among any others, and optionally `label` (integral
/// values) for [`Cloud::labels`].
///
/// Fields may be quoted (RFC 4180, one line per record); columns other than x, y, z
/// and label are not interpreted, but every row must have as many fields as the
/// header. Blank lines are skipped; a leading byte-order mark is tolerated. Unlike
/// [`parse_points_csv`](super::parse_points_csv), which insists on the exact header
/// `x,y,z`, this reads the tables other tools export.
///
/// # Errors
///
/// [`IoError::Format`] (without a path), naming the line: no header or one without
/// x, y and z ([`FormatError::CsvColumns`]); a row with the wrong number of fields;
/// a coordinate that is not a finite number; a label that is not an integer; no rows
/// ([`FormatError::NoPoints`]).
pub fn parse_cloud_csv(text: &str) -> Result<Cloud, IoError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = content_lines(text, 1);
    let at = |n| move |kind| IoError::format(kind, Some(Location::Line(n)));
    let (n, header_line) = lines.next().ok_or(FormatError::NoPoints)?;
    let header = split_record(header_line).map_err(at(n))?;
    let xyz = ["x", "y", "z"].map(|name| column(&header, name));
    let [Some(x), Some(y), Some(z)] = xyz else {
        return Err(at(n)(FormatError::CsvColumns {
            expected: "x, y and z",
            found: excerpt(header_line),
        }));
    };
    let label = column(&header, "label");
    let mut cloud = Cloud {
        points: Vec::new(),
        labels: label.map(|_| Vec::new()),
    };
    for (n, line) in lines {
        let fields = split_record(line).map_err(at(n))?;
        if fields.len() != header.len() {
            return Err(at(n)(FormatError::TokenCount {
                expected: header.len(),
                found: fields.len(),
            }));
        }
        let mut p = [0.0; 3];
        for (c, i) in p.iter_mut().zip([x, y, z]) {
            *c = parse_coordinate(&fields[i]).map_err(at(n))?;
        }
        cloud.points.push(p);
        if let (Some(labels), Some(i)) = (cloud.labels.as_mut(), label) {
            let token = &fields[i];
            let value: f64 = token
                .parse()
                .map_err(|_| at(n)(FormatError::NotANumber(excerpt(token))))?;
            labels.push(label_value(value).map_err(at(n))?);
        }
    }
    if cloud.points.is_empty() {
        return Err(FormatError::NoPoints.into());
    }
    Ok(cloud)
}

/// A label read as a number: integral and in the `i32` range.
pub(super) fn label_value(value: f64) -> Result<i32, FormatError> {
    let fits = value.fract() == 0.0 && f64::from(i32::MIN) <= value && value <= f64::from(i32::MAX);
    // In range and integral: the cast is exact.
    if fits {
        Ok(value as i32)
    } else {
        Err(FormatError::BadLabel(value))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> String {
        parse_cloud_csv(text).unwrap_err().to_string()
    }

    #[test]
    fn columns_by_name_in_any_order() {
        let cloud =
            parse_cloud_csv("\u{feff}id,Z,label,y,X,name\n0,3,2,2,1,\"a,b\"\n\n1,6,5,5,4,c\n")
                .unwrap();
        assert_eq!(cloud.points, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(cloud.labels, Some(vec![2, 5]));
        let plain = parse_cloud_csv("x,y,z\n1,2,3\n").unwrap();
        assert_eq!(plain.labels, None);
        assert_eq!(
            parse_cloud_csv("x,y,z,label\n1,2,3,4.0\n").unwrap().labels,
            Some(vec![4])
        );
    }

    #[test]
    fn errors_name_the_line() {
        assert_eq!(err(""), "no points");
        assert_eq!(err("x,y,z\n"), "no points");
        assert_eq!(
            err("\na,b,c\n1,2,3\n"),
            "line 2: CSV header needs columns x, y and z, found \"a,b,c\""
        );
        assert_eq!(
            err("x,y,z,n\n1,2,3,4\n1,2,3\n"),
            "line 3: expected 4 numbers, found 3"
        );
        assert_eq!(err("x,y,z\n1,q,3\n"), "line 2: \"q\" is not a number");
        assert_eq!(err("x,y,z\n1,nan,3\n"), "line 2: coordinate is not finite");
        assert_eq!(
            err("x,y,z,label\n1,2,3,2.5\n"),
            "line 2: label 2.5 is not an integer"
        );
        assert_eq!(
            err("x,y,z,label\n1,2,3,two\n"),
            "line 2: \"two\" is not a number"
        );
        assert_eq!(
            err("x,y,z\n1,\"2,3\n"),
            "line 2: quoted CSV field has no closing quote"
        );
    }

    #[test]
    fn read_cloud_by_extension() {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("c.TXT");
        std::fs::write(&csv, "x,y,z\n1,2,3\n").unwrap();
        assert_eq!(read_cloud(&csv).unwrap().points, vec![[1.0, 2.0, 3.0]]);
        let xyz = dir.path().join("c.xyzn");
        std::fs::write(&xyz, "1 2 3 0 0 1\n").unwrap();
        assert_eq!(read_cloud(&xyz).unwrap().points, vec![[1.0, 2.0, 3.0]]);
        let ply = dir.path().join("c.ply");
        super::super::write_ply(
            &ply,
            &Cloud {
                points: vec![[1.0, 2.0, 3.0]],
                labels: None,
            },
            super::super::PlyFormat::Ascii,
        )
        .unwrap();
        assert_eq!(read_cloud(&ply).unwrap().points, vec![[1.0, 2.0, 3.0]]);
        let bad = dir.path().join("c.las");
        assert_eq!(
            read_cloud(&bad).unwrap_err().to_string(),
            format!(
                "{}: unknown point cloud file extension \"las\" \
                 (expected .ply, .pcd, .xyz, .xyzn, .xyzrgb, .csv or .txt)",
                bad.display()
            )
        );
        std::fs::write(&csv, "x,y\n1,2\n").unwrap();
        assert!(read_cloud(&csv)
            .unwrap_err()
            .to_string()
            .starts_with(&format!("{}: line 1: ", csv.display())));
    }
}
