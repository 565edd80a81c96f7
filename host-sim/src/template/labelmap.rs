//! A labelled template cloud from a labelmap volume (TotalSegmentator, 3D Slicer).
//!
//! # The rule
//! 1. **Classes.** Voxels are sorted into sternum, costal cartilage and the ribs
//!    `rib_left_1..12` / `rib_right_1..12` by their label values ([`LabelIds`]:
//!    TotalSegmentator v2 ids by default, a name → id map, or the segment names a
//!    `.seg.nrrd` carries). Everything else is background.
//! 2. **Which cartilage is which.** TotalSegmentator's `costal_cartilages` is one mask
//!    for every cartilage, so each cartilage voxel takes the rib it is *geodesically*
//!    nearest to: a Dijkstra spread through the cartilage mask (26-connected, edges as
//!    long as the physical distance between voxel centres, so anisotropic voxels are
//!    right) from the cartilage voxels that touch a rib voxel (the costochondral
//!    junctions). A Euclidean nearest rib would go wrong where the lower cartilages
//!    rise past the ends of the ribs above them; a geodesic path cannot leave the
//!    cartilage. Cartilage no rib reaches is dropped and counted.
//! 3. **Numbering.** The file's rib `rib2` (default 2) is taken as rib 2, and so on:
//!    TotalSegmentator's numbering can be off by one on some scans, and the summary
//!    says which ids were taken. Cartilages of ribs 2..=5 are kept; those of the other
//!    ribs (1, 6, 7, ...) are dropped and counted. A rib 2..=5 whose cartilage is
//!    missing on either side is refused with the rib and side named.
//! 4. **Surface.** A template is a surface cloud: every face between a kept voxel
//!    (sternum or cartilage 2..=5) and a voxel outside them gives a point at the face's
//!    centre, in the patient frame (the volume's affine), labelled 1 (sternum) or with
//!    the rib number. Faces between the sternum and a cartilage are inside the
//!    structure and give none.
//! 5. **Spacing.** The face points are thinned to a Poisson-disc set: visited in a
//!    seeded random order, a point is kept when no kept point lies within `spacing`.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};
use std::fmt;
use std::path::Path;

use crate::error::CliError;
use crate::io::volume::{LabelVolume, TOTALSEGMENTATOR};
use crate::io::Cloud;

/// Sides, in the order of [`LabelIds::ribs`].
pub const SIDES: [&str; 2] = ["left", "right"];
/// Ribs a labelmap may name per side.
pub const RIBS_PER_SIDE: usize = 12;

/// Which label values are which structure.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelIds {
    /// The sternum's values.
    pub sternum: Vec<u16>,
    /// The costal cartilages' values (one mask for all, or one per cartilage).
    pub cartilage: Vec<u16>,
    /// `ribs[side][n - 1]`: the value of rib n on side 0 (left) or 1 (right).
    pub ribs: [[Option<u16>; RIBS_PER_SIDE]; 2],
}

/// The structure a class name denotes, by TotalSegmentator's names (`sternum`,
/// `costal_cartilages`, `rib_left_3`, ...). Case, spaces and hyphens are forgiven.
fn structure(name: &str) -> Option<Structure> {
    let n: String = name
        .trim()
        .to_ascii_lowercase()
        .chars()
        .map(|c| if c == ' ' || c == '-' { '_' } else { c })
        .collect();
    match n.as_str() {
        "sternum" => return Some(Structure::Sternum),
        "costal_cartilages" | "costal_cartilage" => return Some(Structure::Cartilage),
        _ => {}
    }
    for (side, s) in SIDES.iter().enumerate() {
        if let Some(k) = n.strip_prefix(&format!("rib_{s}_")) {
            let k: usize = k.parse().ok()?;
            if (1..=RIBS_PER_SIDE).contains(&k) {
                return Some(Structure::Rib { side, rib: k });
            }
        }
    }
    None
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Structure {
    Sternum,
    Cartilage,
    Rib { side: usize, rib: usize },
}

impl LabelIds {
    /// From `(name, value)` pairs; names unknown to ribreg are ignored.
    pub fn from_names<'a>(pairs: impl IntoIterator<Item = (&'a str, u16)>) -> Self {
        let mut ids = LabelIds {
            sternum: Vec::new(),
            cartilage: Vec::new(),
            ribs: [[None; RIBS_PER_SIDE]; 2],
        };
        for (name, value) in pairs {
            match structure(name) {
                Some(Structure::Sternum) => ids.sternum.push(value),
                Some(Structure::Cartilage) => ids.cartilage.push(value),
                Some(Structure::Rib { side, rib }) => ids.ribs[side][rib - 1] = Some(value),
                None => {}
            }
        }
        ids
    }

    /// TotalSegmentator v2 (`total` task) ids.
    pub fn totalsegmentator() -> Self {
        Self::from_names(TOTALSEGMENTATOR.iter().map(|(n, v)| (*n, *v)))
    }

    /// A JSON object `{"sternum": 116, "costal_cartilages": 117, "rib_left_1": 92, ...}`
    /// (TotalSegmentator's class names) from `path`.
    ///
    /// # Errors
    /// The file cannot be read, is not such an object, or names no sternum or cartilage.
    pub fn from_json(path: &Path) -> Result<Self, CliError> {
        let text =
            std::fs::read_to_string(path).map_err(|e| CliError::input(path, e.to_string()))?;
        let value: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| CliError::input(path, e.to_string()))?;
        let obj = value.as_object().ok_or_else(|| {
            CliError::input(path, "expected a JSON object of class name → label value")
        })?;
        let mut pairs = Vec::new();
        for (name, v) in obj {
            let id = v
                .as_u64()
                .and_then(|v| u16::try_from(v).ok())
                .ok_or_else(|| {
                    CliError::input(
                        path,
                        format!("\"{name}\": {v} is not a label value 0..65535"),
                    )
                })?;
            if structure(name).is_none() {
                return Err(CliError::input(
                    path,
                    format!(
                        "\"{name}\" is not a class ribreg uses (sternum, costal_cartilages, \
                         rib_left_N, rib_right_N)"
                    ),
                ));
            }
            pairs.push((name.as_str(), id));
        }
        let ids = Self::from_names(pairs);
        ids.check().map_err(|m| CliError::input(path, m))?;
        Ok(ids)
    }

    /// Refuses a map without a sternum or a cartilage class.
    fn check(&self) -> Result<(), String> {
        if self.sternum.is_empty() {
            return Err("no sternum class in the label map".into());
        }
        if self.cartilage.is_empty() {
            return Err("no costal_cartilages class in the label map".into());
        }
        Ok(())
    }
}

/// What [`template_from_labelmap`] found, for the one-line summary.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelmapSummary {
    /// Voxel spacing, mm.
    pub spacing: [f64; 3],
    /// Sternum voxels.
    pub sternum_voxels: usize,
    /// Cartilage voxels per anatomical rib 2..=5, per side.
    pub cartilage_voxels: [[usize; 4]; 2],
    /// Cartilage voxels dropped: reached from another rib (1, 6, 7, ...).
    pub other_cartilage_voxels: usize,
    /// Cartilage voxels no rib reaches.
    pub unreached_voxels: usize,
    /// The label values taken as rib 2, left and right.
    pub rib2_ids: [u16; 2],
    /// The file's rib number taken as rib 2.
    pub rib2: usize,
}

impl fmt::Display for LabelmapSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [dx, dy, dz] = self.spacing;
        write!(
            f,
            "labelmap {dx:.2} × {dy:.2} × {dz:.2} mm voxels: sternum {} voxels; cartilage (left/right) ",
            self.sternum_voxels
        )?;
        for r in 0..4 {
            write!(
                f,
                "{}{}: {}/{}",
                if r == 0 { "" } else { ", " },
                r + 2,
                self.cartilage_voxels[0][r],
                self.cartilage_voxels[1][r]
            )?;
        }
        write!(
            f,
            "; dropped {} of other ribs, {} touching no rib; rib 2 = the file's rib {} (ids {}/{})",
            self.other_cartilage_voxels,
            self.unreached_voxels,
            self.rib2,
            self.rib2_ids[0],
            self.rib2_ids[1]
        )
    }
}

/// Voxel classes in the working crop.
const BACKGROUND: u8 = 0;
const STERNUM: u8 = 1;
const CARTILAGE: u8 = 2;
/// Rib classes: `RIB0 + side * 12 + (n - 1)`.
const RIB0: u8 = 8;

/// The labelled template cloud of `volume` (see the module docs for the rule).
///
/// # Errors
/// [`CliError::Input`] (with `path`) naming what is missing: no sternum voxels, no
/// cartilage voxels, a rib 2..=5 without its label in the map, or a cartilage of rib
/// 2..=5 that no voxel of the cartilage mask reaches on a side; `rib2` outside 1..=9.
pub fn template_from_labelmap(
    volume: &LabelVolume,
    ids: &LabelIds,
    rib2: usize,
    spacing: f64,
    path: &Path,
) -> Result<(Cloud, LabelmapSummary), CliError> {
    let fail = |m: String| CliError::input(path, m);
    if !(1..=RIBS_PER_SIDE - 3).contains(&rib2) {
        return Err(CliError::value(format!(
            "--rib2 {rib2}: the rib taken as rib 2 must be 1..={}",
            RIBS_PER_SIDE - 3
        )));
    }
    for (side, s) in SIDES.iter().enumerate() {
        for n in rib2..rib2 + 4 {
            if ids.ribs[side][n - 1].is_none() {
                return Err(fail(format!("the label map names no rib_{s}_{n}")));
            }
        }
    }
    // Class of each label value.
    let mut class_of = HashMap::new();
    for v in &ids.cartilage {
        class_of.insert(*v, CARTILAGE);
    }
    for v in &ids.sternum {
        class_of.insert(*v, STERNUM);
    }
    for (side, ribs) in ids.ribs.iter().enumerate() {
        for (k, v) in ribs.iter().enumerate() {
            if let Some(v) = v {
                // side ≤ 1, k < 12: fits.
                class_of.insert(*v, RIB0 + (side * RIBS_PER_SIDE + k) as u8);
            }
        }
    }
    let [nx, ny, nz] = volume.dims;
    let class = |l: u16| class_of.get(&l).copied().unwrap_or(BACKGROUND);
    // The crop: sternum and cartilage voxels, one voxel of margin for the rib contacts.
    let mut lo = [usize::MAX; 3];
    let mut hi = [0usize; 3];
    let mut any = [false; 3];
    for (i, &l) in volume.labels.iter().enumerate() {
        let c = class(l);
        if c == STERNUM || c == CARTILAGE {
            any[c as usize] = true;
            let ijk = [i % nx, (i / nx) % ny, i / (nx * ny)];
            for a in 0..3 {
                lo[a] = lo[a].min(ijk[a]);
                hi[a] = hi[a].max(ijk[a]);
            }
        }
    }
    if !any[STERNUM as usize] {
        return Err(fail(
            "no sternum voxels (is this the right label map?)".into(),
        ));
    }
    if !any[CARTILAGE as usize] {
        return Err(fail("no costal cartilage voxels".into()));
    }
    let dims = [nx, ny, nz];
    for a in 0..3 {
        lo[a] = lo[a].saturating_sub(1);
        hi[a] = (hi[a] + 1).min(dims[a] - 1);
    }
    let cd = [hi[0] - lo[0] + 1, hi[1] - lo[1] + 1, hi[2] - lo[2] + 1];
    let cidx = |c: [usize; 3]| c[0] + cd[0] * (c[1] + cd[1] * c[2]);
    let mut crop = vec![BACKGROUND; cd[0] * cd[1] * cd[2]];
    for k in 0..cd[2] {
        for j in 0..cd[1] {
            let row = lo[0] + nx * (lo[1] + j + ny * (lo[2] + k));
            for i in 0..cd[0] {
                crop[cidx([i, j, k])] = class(volume.labels[row + i]);
            }
        }
    }
    // 26-neighbour offsets with their physical lengths.
    let mut steps: Vec<([isize; 3], f64)> = Vec::with_capacity(26);
    for dk in -1isize..=1 {
        for dj in -1isize..=1 {
            for di in -1isize..=1 {
                if (di, dj, dk) == (0, 0, 0) {
                    continue;
                }
                let d = [di as f64, dj as f64, dk as f64];
                let len = (0..3)
                    .map(|r| {
                        let v: f64 = (0..3).map(|c| volume.linear[r][c] * d[c]).sum();
                        v * v
                    })
                    .sum::<f64>()
                    .sqrt();
                steps.push(([di, dj, dk], len));
            }
        }
    }
    let neighbour = |c: [usize; 3], d: [isize; 3]| -> Option<[usize; 3]> {
        let mut out = [0; 3];
        for a in 0..3 {
            let v = c[a].checked_add_signed(d[a])?;
            if v >= cd[a] {
                return None;
            }
            out[a] = v;
        }
        Some(out)
    };
    let coords = |i: usize| [i % cd[0], (i / cd[0]) % cd[1], i / (cd[0] * cd[1])];
    // Seeds: cartilage voxels touching a rib (the rib with the most touching voxels).
    // Dijkstra keyed by distance bits (non-negative f64s order as their bits).
    let mut owner = vec![u8::MAX; crop.len()];
    let mut dist = vec![f64::INFINITY; crop.len()];
    let mut heap = BinaryHeap::new();
    for (i, &c) in crop.iter().enumerate() {
        if c != CARTILAGE {
            continue;
        }
        let mut count = [0u8; 2 * RIBS_PER_SIDE];
        for (d, _) in &steps {
            if let Some(n) = neighbour(coords(i), *d) {
                let cn = crop[cidx(n)];
                if cn >= RIB0 {
                    count[(cn - RIB0) as usize] += 1;
                }
            }
        }
        if let Some((rib, _)) = count
            .iter()
            .enumerate()
            .filter(|(_, n)| **n > 0)
            .max_by_key(|(r, n)| (**n, Reverse(*r)))
        {
            // rib < 24: fits.
            owner[i] = rib as u8;
            dist[i] = 0.0;
            heap.push(Reverse((0u64, i)));
        }
    }
    while let Some(Reverse((bits, i))) = heap.pop() {
        let d = f64::from_bits(bits);
        if d > dist[i] {
            continue;
        }
        let c = coords(i);
        for (step, len) in &steps {
            let Some(n) = neighbour(c, *step) else {
                continue;
            };
            let ni = cidx(n);
            if crop[ni] != CARTILAGE {
                continue;
            }
            let nd = d + len;
            if nd < dist[ni] {
                dist[ni] = nd;
                owner[ni] = owner[i];
                heap.push(Reverse((nd.to_bits(), ni)));
            }
        }
    }
    // Labels per crop voxel: 1 sternum, 2..=5 kept cartilage, 0 otherwise.
    let mut summary = LabelmapSummary {
        spacing: volume.spacing(),
        sternum_voxels: 0,
        cartilage_voxels: [[0; 4]; 2],
        other_cartilage_voxels: 0,
        unreached_voxels: 0,
        // Checked above: every rib rib2..rib2+3 has an id.
        rib2_ids: [0, 1].map(|s| ids.ribs[s][rib2 - 1].unwrap_or(0)),
        rib2,
    };
    let mut label = vec![0u8; crop.len()];
    for (i, &c) in crop.iter().enumerate() {
        if c == STERNUM {
            label[i] = 1;
            summary.sternum_voxels += 1;
        } else if c == CARTILAGE {
            if owner[i] == u8::MAX {
                summary.unreached_voxels += 1;
                continue;
            }
            let side = usize::from(owner[i]) / RIBS_PER_SIDE;
            let n = usize::from(owner[i]) % RIBS_PER_SIDE + 1;
            if (rib2..rib2 + 4).contains(&n) {
                let r = n - rib2;
                summary.cartilage_voxels[side][r] += 1;
                // r < 4: the label is 2..=5.
                label[i] = (r + 2) as u8;
            } else {
                summary.other_cartilage_voxels += 1;
            }
        }
    }
    for (side, s) in SIDES.iter().enumerate() {
        for r in 0..4 {
            if summary.cartilage_voxels[side][r] == 0 {
                return Err(fail(format!(
                    "rib {} not found on the {s}: no cartilage voxel touches rib_{s}_{} (id {})",
                    r + 2,
                    rib2 + r,
                    ids.ribs[side][rib2 + r - 1].unwrap_or(0)
                )));
            }
        }
    }
    // Face points between kept and not-kept voxels.
    let mut points = Vec::new();
    let mut labels = Vec::new();
    const FACES: [[isize; 3]; 6] = [
        [1, 0, 0],
        [-1, 0, 0],
        [0, 1, 0],
        [0, -1, 0],
        [0, 0, 1],
        [0, 0, -1],
    ];
    for (i, &l) in label.iter().enumerate() {
        if l == 0 {
            continue;
        }
        let c = coords(i);
        for f in FACES {
            let outside = neighbour(c, f).is_none_or(|n| label[cidx(n)] == 0);
            if outside {
                let v = [0, 1, 2].map(|a| (lo[a] + c[a]) as f64 + 0.5 * f[a] as f64);
                let p: [f64; 3] = std::array::from_fn(|r| {
                    (0..3).map(|a| volume.linear[r][a] * v[a]).sum::<f64>() + volume.offset[r]
                });
                points.push(p);
                labels.push(i32::from(l));
            }
        }
    }
    let keep = poisson_thin(&points, spacing, 0x7e3a_1b2c);
    let cloud = Cloud {
        points: keep.iter().map(|&i| points[i]).collect(),
        labels: Some(keep.iter().map(|&i| labels[i]).collect()),
    };
    Ok((cloud, summary))
}

/// Indices of a Poisson-disc subset of `points`: visited in a seeded random order, a
/// point is kept when no kept point lies within `spacing`. Kept indices are returned in
/// ascending order.
pub fn poisson_thin(points: &[[f64; 3]], spacing: f64, seed: u64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len()).collect();
    let mut rng = ribreg_core::math::rng::Rng::new(seed);
    for i in (1..order.len()).rev() {
        let j = rng.below(u32::try_from(i + 1).unwrap_or(u32::MAX)) as usize;
        order.swap(i, j);
    }
    let cell = |p: &[f64; 3]| p.map(|c| (c / spacing).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    let mut kept = Vec::new();
    let s2 = spacing * spacing;
    for i in order {
        let p = &points[i];
        let c = cell(p);
        let mut free = true;
        'search: for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(list) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        for &k in list {
                            let q = &points[k];
                            let d2: f64 = (0..3).map(|a| (p[a] - q[a]).powi(2)).sum();
                            if d2 < s2 {
                                free = false;
                                break 'search;
                            }
                        }
                    }
                }
            }
        }
        if free {
            grid.entry(c).or_default().push(i);
            kept.push(i);
        }
    }
    kept.sort_unstable();
    kept
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::phantom::{ct, SubjectParams};

    fn ids() -> LabelIds {
        LabelIds::from_names(
            [("sternum", 116u16), ("costal_cartilages", 117)]
                .into_iter()
                .chain((1..=12u16).map(|n| {
                    (
                        [
                            "rib_left_1",
                            "rib_left_2",
                            "rib_left_3",
                            "rib_left_4",
                            "rib_left_5",
                            "rib_left_6",
                            "rib_left_7",
                            "rib_left_8",
                            "rib_left_9",
                            "rib_left_10",
                            "rib_left_11",
                            "rib_left_12",
                        ][usize::from(n - 1)],
                        91 + n,
                    )
                }))
                .chain((1..=12u16).map(|n| {
                    (
                        [
                            "rib_right_1",
                            "rib_right_2",
                            "rib_right_3",
                            "rib_right_4",
                            "rib_right_5",
                            "rib_right_6",
                            "rib_right_7",
                            "rib_right_8",
                            "rib_right_9",
                            "rib_right_10",
                            "rib_right_11",
                            "rib_right_12",
                        ][usize::from(n - 1)],
                        103 + n,
                    )
                })),
        )
    }

    #[test]
    fn phantom_labelmap_gives_the_phantom_template() {
        let t0 = std::time::Instant::now();
        let params = SubjectParams::template();
        let vol = ct::labelmap(&params);
        eprintln!("labelmap {:?} in {:?}", vol.dims, t0.elapsed());
        let (cloud, summary) =
            template_from_labelmap(&vol, &ids(), 2, 2.5, Path::new("phantom")).unwrap();
        eprintln!(
            "{summary}\n{} points in {:?}",
            cloud.points.len(),
            t0.elapsed()
        );
        assert!(
            summary.other_cartilage_voxels > 0,
            "distractors are dropped"
        );
        // Every point lies on the phantom part of its label, within a voxel.
        let dense = crate::phantom::PhantomConfig {
            spacing_mm: 1.0,
            ..Default::default()
        };
        let pair_cloud = crate::phantom::PhantomPair::generate(&dense).template;
        let mut far = 0;
        let mut dists = Vec::new();
        let mut wrong = 0;
        let labels = cloud.labels.as_ref().unwrap();
        for (p, l) in cloud.points.iter().zip(labels) {
            let q = [0, 1, 2].map(|a| p[a] - ct::WORLD_SHIFT_MM[a]);
            let (d, nearest_label) = pair_cloud
                .points
                .iter()
                .zip(&pair_cloud.labels)
                .map(|(r, &rl)| {
                    let d2: f64 = (0..3).map(|a| (r[a] - q[a]).powi(2)).sum();
                    (d2.sqrt(), rl)
                })
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .unwrap();
            dists.push(d);
            // Points on the interchondral bridge's upper half are cartilage 5's, and
            // on no phantom part.
            if d > 3.0 {
                far += 1;
            } else if nearest_label != *l {
                wrong += 1;
            }
        }
        dists.sort_by(f64::total_cmp);
        let median = dists[dists.len() / 2];
        let n = cloud.points.len() as f64;
        eprintln!("median distance to the phantom template {median:.2} mm, {far} points > 3 mm, {wrong} labels differ");
        // Face centres sit on the voxelised surface, within a voxel of the true one; the
        // 1 mm phantom sampling adds ~0.4 mm.
        assert!(median < 1.0, "{median}");
        assert!((far as f64) < 0.02 * n, "{far}");
        assert!((wrong as f64) < 0.02 * cloud.points.len() as f64, "{wrong}");
    }
}
