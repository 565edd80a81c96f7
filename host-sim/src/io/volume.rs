//! Labelmap volumes (placeholder of the struct until the readers land).

use super::Space;

/// A labelled voxel volume in ribreg's patient frame.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelVolume {
    /// Voxels along i, j, k.
    pub dims: [usize; 3],
    /// One label per voxel, i fastest: index = i + dims[0] * (j + dims[1] * k).
    pub labels: Vec<u16>,
    /// Voxel (i, j, k) centre → patient frame, mm: p = linear · [i, j, k] + offset.
    pub linear: [[f64; 3]; 3],
    /// See `linear`.
    pub offset: [f64; 3],
    /// The world system the file declared.
    pub space: Space,
    /// Segment names and their label values when the file names them.
    pub segments: Vec<(String, u16)>,
}

impl LabelVolume {
    /// Patient-frame position of voxel (i, j, k)'s centre.
    pub fn position(&self, ijk: [usize; 3]) -> [f64; 3] {
        let v = ijk.map(|c| c as f64);
        std::array::from_fn(|r| {
            self.linear[r][0] * v[0]
                + self.linear[r][1] * v[1]
                + self.linear[r][2] * v[2]
                + self.offset[r]
        })
    }

    /// Voxel spacing along i, j, k, mm.
    pub fn spacing(&self) -> [f64; 3] {
        std::array::from_fn(|c| {
            (0..3)
                .map(|r| self.linear[r][c] * self.linear[r][c])
                .sum::<f64>()
                .sqrt()
        })
    }
}

/// TotalSegmentator v2 `total` ids of the classes ribreg uses.
pub const TOTALSEGMENTATOR: &[(&str, u16)] = &[];
