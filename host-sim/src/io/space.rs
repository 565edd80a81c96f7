//! Anatomical coordinate systems and the one conversion into ribreg's patient frame.
//!
//! ribreg's patient frame (every cloud, mesh and waypoint the registration sees) is
//! right-handed, in mm: **x** toward the patient's left, **y** cranial (superior), **z**
//! anterior (toward the probe). Medical files use one of two world systems:
//!
//! | system | +x | +y | +z | written by | to the patient frame |
//! |---|---|---|---|---|---|
//! | RAS | right | anterior | superior | NIfTI (`sform`/`qform`), older Slicer files | (−x, z, y) |
//! | LPS | left | posterior | superior | DICOM, ITK, NRRD (`space: left-posterior-superior`), Slicer ≥ 4.11 markups and STL | (x, z, −y) |
//!
//! Both are proper rotations (determinant +1), so a conversion never mirrors a patient:
//! a left–right flip is the one error a registration cannot undo (the chest is nearly
//! symmetric, so a mirrored template registers "well" and carries a plan planned on the
//! left onto the right). Every reader therefore converts explicitly, from the system its
//! file declares, and a file that declares none is taken to be in the patient frame
//! only where its format is ribreg's own (PLY, CSV written by ribreg) or the user says so.
//! The translation is untouched: the template keeps the scanner's world position, and
//! waypoints exported from the same scene land on it after the same conversion.

/// A world coordinate system a file can declare.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Space {
    /// ribreg's patient frame: x left, y cranial, z anterior.
    Patient,
    /// Right, anterior, superior (NIfTI, older Slicer files).
    Ras,
    /// Left, posterior, superior (DICOM, ITK, NRRD, Slicer).
    Lps,
}

impl Space {
    /// The space named in a file: `RAS`, `LPS` (any case), NRRD's long names
    /// (`right-anterior-superior`, `left-posterior-superior`), Slicer's legacy codes
    /// (`0` = RAS, `1` = LPS) or ribreg's own `patient`. `None` for anything else.
    pub fn parse(name: &str) -> Option<Space> {
        match name.trim().to_ascii_lowercase().as_str() {
            "ras" | "right-anterior-superior" | "0" => Some(Space::Ras),
            "lps" | "left-posterior-superior" | "1" => Some(Space::Lps),
            "patient" => Some(Space::Patient),
            _ => None,
        }
    }

    /// The short name (`patient`, `RAS`, `LPS`).
    pub fn name(self) -> &'static str {
        match self {
            Space::Patient => "patient",
            Space::Ras => "RAS",
            Space::Lps => "LPS",
        }
    }

    /// The point (or direction) `p`, given in this space, in the patient frame.
    pub fn to_patient(self, p: [f64; 3]) -> [f64; 3] {
        match self {
            Space::Patient => p,
            Space::Ras => [-p[0], p[2], p[1]],
            Space::Lps => [p[0], p[2], -p[1]],
        }
    }

    /// The inverse of [`Space::to_patient`]: a patient-frame point in this space.
    pub fn from_patient(self, p: [f64; 3]) -> [f64; 3] {
        match self {
            Space::Patient => p,
            Space::Ras => [-p[0], p[2], p[1]],
            Space::Lps => [p[0], -p[2], p[1]],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Space;

    #[test]
    fn conversions_are_proper_and_invert() {
        let p = [1.0, 2.0, 3.0];
        for s in [Space::Patient, Space::Ras, Space::Lps] {
            assert_eq!(s.from_patient(s.to_patient(p)), p, "{}", s.name());
            assert_eq!(s.to_patient(s.from_patient(p)), p, "{}", s.name());
            // The images of the basis vectors form a right-handed frame (no mirror).
            let [a, b, c] =
                [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].map(|e| s.to_patient(e));
            let cross = [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ];
            assert_eq!(cross, c, "{} is a mirror", s.name());
        }
        // The patient's left is +x in LPS and −x in RAS; superior is +z in both.
        assert_eq!(Space::Lps.to_patient([10.0, 0.0, 0.0]), [10.0, 0.0, 0.0]);
        assert_eq!(Space::Ras.to_patient([-10.0, 0.0, 0.0]), [10.0, 0.0, 0.0]);
        assert_eq!(Space::Ras.to_patient([0.0, 5.0, 0.0]), [0.0, 0.0, 5.0]); // anterior
        assert_eq!(Space::Lps.to_patient([0.0, -5.0, 0.0]), [0.0, 0.0, 5.0]); // anterior
        assert_eq!(Space::parse("left-posterior-superior"), Some(Space::Lps));
        assert_eq!(Space::parse("0"), Some(Space::Ras));
        assert_eq!(Space::parse("LPI"), None);
    }
}
