//! Probe targets: a mapped waypoint becomes a TCP pose on the skin side of the local bone
//! surface, at the configured standoff, its beam along the surface's inward normal and
//! its footprint along the gap (the principal axes of the cloud within
//! [`PATCH_RADIUS_MM`]), with the local rigid fit's RMS residual as its quality and
//! whether the sweep reaches it ([`crate::registration::reach`]).

use super::Settings;
use crate::error::{Error, Result};
use crate::math::geom::Rigid;
use crate::registration::pipeline::{Registration, Template};
use crate::registration::reach::WaypointReach;
use crate::Vec3;
use nalgebra::{Matrix3, SymmetricEigen};

/// Radius of the bone-surface patch whose principal axes orient a probe target, mm.
pub const PATCH_RADIUS_MM: f32 = 12.0;
/// Fewest cloud points in the patch; below it the probe axis points straight at the
/// sweep's mean probe position.
const MIN_PATCH_POINTS: usize = 6;

/// A probe target: where the TCP goes for one mapped waypoint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeTarget {
    /// The mapped waypoint (on the bone surface level), base frame, mm.
    pub waypoint: Vec3,
    /// TCP pose: on the skin side at the configured standoff, beam along the inward
    /// surface normal.
    pub tcp: Rigid,
    /// Quality: RMS residual of the rigid fit over the waypoint's skeleton neighbourhood
    /// (how far the skeleton around it is from moving rigidly), mm; the waypoint itself
    /// is mapped by [`Registration::carry`].
    pub quality_mm: f32,
    /// How far it lies beyond what the sweep shows of its gap ([`WaypointReach`]; `None`
    /// for a registration without rib extents).
    pub reach: Option<WaypointReach>,
    /// Whether the probe is driven there: `false` only in a partial plan, for a waypoint
    /// [`WaypointReach::supported`] marks.
    pub supported: bool,
}

/// Maps one waypoint and turns it into a probe target.
#[inline(never)]
#[allow(clippy::too_many_arguments)]
pub(super) fn target(
    reg: &Registration,
    template: &Template,
    w: &Vec3,
    t: Rigid,
    mask: u32,
    cloud: &[Vec3],
    settings: Option<&Settings>,
    probe_sum: Vec3,
    probe_count: u32,
) -> Result<ProbeTarget> {
    let s = settings.ok_or(Error::Config("no configuration"))?;
    let skin = if probe_count > 0 {
        probe_sum / probe_count as f32
    } else {
        Vec3::zeros()
    };
    let quality_mm = reg.map.residual(&t, mask);
    let p = reg.carry(w, &t);
    let tcp = probe_pose(cloud, &p, &skin, s.standoff);
    Ok(ProbeTarget {
        waypoint: p,
        tcp,
        quality_mm,
        reach: WaypointReach::of(template, reg, w, &p),
        supported: true,
    })
}

/// The TCP pose aiming at `p` on the bone surface: local surface normal and gap
/// direction from the principal axes of the cloud within [`PATCH_RADIUS_MM`], the normal
/// oriented toward `skin` (the sweep's mean probe position), the TCP `standoff` mm out
/// along it, its beam (z) along the inward normal, its footprint (x) along the gap.
pub fn probe_pose(cloud: &[Vec3], p: &Vec3, skin: &Vec3, standoff: f32) -> Rigid {
    let r2 = PATCH_RADIUS_MM * PATCH_RADIUS_MM;
    let (mut sum, mut n) = (Vec3::zeros(), 0usize);
    for q in cloud.iter().filter(|q| (*q - p).norm_squared() <= r2) {
        sum += q;
        n += 1;
    }
    let up = (skin - p).try_normalize(1e-6).unwrap_or(Vec3::z());
    let (mut normal, mut along) = (up, up.cross(&Vec3::x()));
    if n >= MIN_PATCH_POINTS {
        let mean = sum / n as f32;
        let mut cov = Matrix3::zeros();
        for q in cloud.iter().filter(|q| (*q - p).norm_squared() <= r2) {
            let d = q - mean;
            cov += d * d.transpose();
        }
        let eig = SymmetricEigen::new(cov);
        normal = eig.eigenvectors.column(eig.eigenvalues.imin()).into_owned();
        along = eig.eigenvectors.column(eig.eigenvalues.imax()).into_owned();
    }
    if normal.dot(&up) < 0.0 {
        normal = -normal;
    }
    let z = -normal;
    let x = (along - z * along.dot(&z))
        .try_normalize(1e-6)
        .or_else(|| z.cross(&Vec3::y()).try_normalize(1e-6))
        .unwrap_or(Vec3::x());
    let y = z.cross(&x);
    Rigid {
        rotation: Matrix3::from_columns(&[x, y, z]),
        translation: p + normal * standoff,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn probe_pose_stands_off_along_the_outward_normal() {
        // A flat patch in z = 0; the skin is above.
        let mut cloud = std::vec::Vec::new();
        for i in 0..20 {
            for j in 0..8 {
                cloud.push(Vec3::new(i as f32 - 10.0, (j as f32 - 4.0) * 0.5, 0.0));
            }
        }
        let t = probe_pose(&cloud, &Vec3::zeros(), &Vec3::new(0.0, 0.0, 50.0), 15.0);
        assert!((t.translation - Vec3::new(0.0, 0.0, 15.0)).norm() < 1e-4);
        assert!((t.rotation.column(2) - Vec3::new(0.0, 0.0, -1.0)).norm() < 1e-4);
        assert!(
            t.rotation.column(0).x.abs() > 0.999,
            "footprint along the long axis"
        );
        assert!((t.rotation.determinant() - 1.0).abs() < 1e-4);
    }
}
