//! Open3D's plain-text clouds: `.xyz` (`x y z` per line), `.xyzn` (`x y z nx ny nz`),
//! `.xyzrgb` (`x y z r g b`).

use std::path::Path;

use super::{content_lines, excerpt, parse_coordinate, read_bytes, text};
use super::{Cloud, FormatError, IoError, Location};

/// Parse an XYZ point cloud: one point per line, whitespace-separated numbers, the
/// first three being x, y, z (mm).
///
/// Further numbers on a line (normals in `.xyzn`, colours in `.xyzrgb`) are checked to
/// be numbers and otherwise ignored. Blank lines and lines starting with `#` are
/// skipped; CRLF endings and a leading byte-order mark are tolerated. The result has no
/// labels.
///
/// # Errors
///
/// [`IoError::Format`] (without a path), naming the line: fewer than three numbers, a
/// token that is not a number, a non-finite coordinate; [`FormatError::NoPoints`] when
/// no line holds a point.
pub fn parse_xyz(text: &str) -> Result<Cloud, IoError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut points = Vec::new();
    for (n, line) in content_lines(text, 1) {
        if line.starts_with('#') {
            continue;
        }
        let at = |kind| IoError::format(kind, Some(Location::Line(n)));
        let tokens: Vec<&str> = line.split_whitespace().collect();
        if tokens.len() < 3 {
            return Err(at(FormatError::TokenCount {
                expected: 3,
                found: tokens.len(),
            }));
        }
        let mut p = [0.0; 3];
        for (c, token) in p.iter_mut().zip(&tokens) {
            *c = parse_coordinate(token).map_err(at)?;
        }
        if let Some(bad) = tokens[3..].iter().find(|t| t.parse::<f64>().is_err()) {
            return Err(at(FormatError::NotANumber(excerpt(bad))));
        }
        points.push(p);
    }
    if points.is_empty() {
        return Err(FormatError::NoPoints.into());
    }
    Ok(Cloud {
        points,
        labels: None,
    })
}

/// Read an XYZ point cloud from `path`; see [`parse_xyz`].
///
/// # Errors
///
/// [`IoError::Io`] if the file cannot be read; [`IoError::Format`] with the path
/// attached if it is not UTF-8 or [`parse_xyz`] rejects it.
pub fn read_xyz(path: &Path) -> Result<Cloud, IoError> {
    let bytes = read_bytes(path)?;
    text(&bytes, 1)
        .and_then(parse_xyz)
        .map_err(|e| e.with_path(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_three_and_six_columns() {
        let text = "# written by hand\r\n1 2 3\r\n\r\n  4\t5 6 0 0 1\n-1e-3 0.5 7 255 0 12\n";
        let cloud = parse_xyz(text).unwrap();
        assert_eq!(
            cloud.points,
            vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [-0.001, 0.5, 7.0]]
        );
        assert_eq!(cloud.labels, None);
    }

    #[test]
    fn errors_name_the_line() {
        let err = |t: &str| parse_xyz(t).unwrap_err().to_string();
        assert_eq!(err("1 2 3\n4 5\n"), "line 2: expected 3 numbers, found 2");
        assert_eq!(
            err("1 2 3\n\n1,2,3\n"),
            "line 3: expected 3 numbers, found 1"
        );
        assert_eq!(err("1 2 x\n"), "line 1: \"x\" is not a number");
        assert_eq!(err("1 2 3 0 n 1\n"), "line 1: \"n\" is not a number");
        assert_eq!(err("1 inf 3\n"), "line 1: coordinate is not finite");
        assert_eq!(err(""), "no points");
        assert_eq!(err("# only a comment\n\n"), "no points");
    }

    #[test]
    fn read_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.xyz");
        std::fs::write(&path, "1 2 3\n\u{0}\n").unwrap();
        assert_eq!(
            read_xyz(&path).unwrap_err().to_string(),
            format!("{}: line 2: expected 3 numbers, found 1", path.display())
        );
        std::fs::write(&path, b"1 2 3\n\xff\n").unwrap();
        assert_eq!(
            read_xyz(&path).unwrap_err().to_string(),
            format!("{}: line 2: text is not valid UTF-8", path.display())
        );
    }
}
