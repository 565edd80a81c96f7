//! Spatial calibration of the robot-held probe (paper Eq. 1): pixel → image plane → robot
//! base, `b_T_us = b_T_ee · ee_T_tcp · tcp_T_us`.
//!
//! # Frames
//! * **Image** `{us}`: origin at the image's top-left corner (pixel (0, 0) at the probe face,
//!   first element), `x` along a row (the footprint, increasing column `u`), `y` down the
//!   image (depth, increasing row `v`), `z = x × y` (the elevation direction). Pixel
//!   coordinates are continuous: `(u, v)` maps to `(u · s_x, v · s_y, 0)` mm with the pixel
//!   scale `s_x = footprint / width`, `s_y = depth / height`, and is accepted for
//!   `0 ≤ u ≤ width`, `0 ≤ v ≤ height`.
//! * **TCP** `{tcp}`: the tool centre point, conventionally the middle of the probe face,
//!   `z` along the beam into the body, `x` along the footprint. [`Calibration::tcp_t_us`]
//!   places the image in it; for that convention it is a rotation taking image `x` to TCP
//!   `x` and image `y` to TCP `z`, and a translation of `−footprint/2` along TCP `x`
//!   ([`Calibration::centred`]).
//! * **End-effector** `{ee}`: the robot flange; [`Calibration::ee_t_tcp`] is the holder.
//! * **Base** `{b}`: the robot base; the robot reports `b_T_ee` per pose.

use crate::error::{Error, Result};
use crate::math::geom::is_proper_rigid;
use crate::math::geom::Rigid;
use crate::Vec3;
use nalgebra::Matrix3;

/// Largest footprint or imaging depth accepted, mm (a probe image is never a metre wide).
pub const MAX_PROBE_MM: f32 = 1000.0;

/// The image geometry of a linear probe (also its wire and JSON form: the field names are
/// the keys of `probe.json`'s `probe` object).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProbeModel {
    /// Image width, pixels (columns, along the footprint).
    pub width_px: u16,
    /// Image height, pixels (rows, along the depth).
    pub height_px: u16,
    /// Probe footprint: the width the image covers, mm.
    pub footprint_mm: f32,
    /// Imaging depth: the height the image covers, mm.
    pub depth_mm: f32,
}

impl ProbeModel {
    /// A 12L3-like linear probe at 0.1 mm per pixel: 384 × 350 pixels over a 38.4 mm
    /// footprint and the paper's 35 mm imaging depth.
    pub const LINEAR_38MM: ProbeModel = ProbeModel {
        width_px: 384,
        height_px: 350,
        footprint_mm: 38.4,
        depth_mm: 35.0,
    };

    /// Checks sizes: at least one pixel each way, footprint and depth finite, positive and
    /// at most [`MAX_PROBE_MM`].
    pub fn validate(&self) -> Result<()> {
        if self.width_px == 0 || self.height_px == 0 {
            return Err(Error::Config("probe image must be at least 1×1 pixels"));
        }
        let ok = |v: f32| v.is_finite() && v > 0.0 && v <= MAX_PROBE_MM;
        if !ok(self.footprint_mm) || !ok(self.depth_mm) {
            return Err(Error::Config(
                "probe footprint and depth must be finite, positive and at most 1000 mm",
            ));
        }
        Ok(())
    }

    /// Pixel scale `(s_x, s_y)`, mm per pixel along a row and down a column.
    pub fn scale(&self) -> (f32, f32) {
        (
            self.footprint_mm / f32::from(self.width_px),
            self.depth_mm / f32::from(self.height_px),
        )
    }

    /// The image-plane point of pixel `(u, v)`, or `None` if the pixel is not finite or
    /// outside `[0, width] × [0, height]`.
    pub fn pixel_to_image(&self, u: f32, v: f32) -> Option<Vec3> {
        let inside = |x: f32, hi: u16| x.is_finite() && (0.0..=f32::from(hi)).contains(&x);
        if !inside(u, self.width_px) || !inside(v, self.height_px) {
            return None;
        }
        let (sx, sy) = self.scale();
        Some(Vec3::new(u * sx, v * sy, 0.0))
    }
}

/// The probe's spatial calibration: image geometry, image → TCP and TCP → flange.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    /// Image geometry.
    pub probe: ProbeModel,
    /// Image frame in the TCP frame (`tcp_T_us`).
    pub tcp_t_us: Rigid,
    /// TCP frame in the end-effector (flange) frame (`ee_T_tcp`, the holder).
    pub ee_t_tcp: Rigid,
}

impl Calibration {
    /// The conventional image placement for `probe`: TCP at the middle of the probe face,
    /// image `x` = TCP `x` (footprint), image `y` = TCP `z` (beam), image origin at
    /// `−footprint/2` along TCP `x`; holder `ee_t_tcp`.
    pub fn centred(probe: ProbeModel, ee_t_tcp: Rigid) -> Calibration {
        // Columns are the images of the image axes in TCP: x → x, y → z, z = x × y → −y.
        let rotation = Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0);
        Calibration {
            probe,
            tcp_t_us: Rigid {
                rotation,
                translation: Vec3::new(-0.5 * probe.footprint_mm, 0.0, 0.0),
            },
            ee_t_tcp,
        }
    }

    /// Checks the probe and both transforms (finite, rotations proper within
    /// [`ROTATION_TOLERANCE`](crate::math::geom::ROTATION_TOLERANCE), translations within [`crate::limits::MAX_COORD_MM`]).
    pub fn validate(&self) -> Result<()> {
        self.probe.validate()?;
        for (t, what) in [
            (
                &self.tcp_t_us,
                "tcp_T_us must be a finite proper rigid transform",
            ),
            (
                &self.ee_t_tcp,
                "ee_T_tcp must be a finite proper rigid transform",
            ),
        ] {
            if !is_proper_rigid(t) {
                return Err(Error::Config(what));
            }
        }
        Ok(())
    }

    /// `ee_T_us = ee_T_tcp · tcp_T_us`, constant for a calibration.
    pub fn ee_t_us(&self) -> Rigid {
        self.ee_t_tcp.after(&self.tcp_t_us)
    }

    /// `b_T_us = b_T_ee · ee_T_tcp · tcp_T_us` for the flange pose `b_t_ee` (paper Eq. 1).
    pub fn b_t_us(&self, b_t_ee: &Rigid) -> Rigid {
        b_t_ee.after(&self.ee_t_us())
    }

    /// Pixel `(u, v)` of an image taken at flange pose `b_t_ee`, in the robot base frame;
    /// `None` if the pixel is outside the image or not finite.
    pub fn pixel_to_base(&self, b_t_ee: &Rigid, u: f32, v: f32) -> Option<Vec3> {
        let p = self.probe.pixel_to_image(u, v)?;
        Some(self.b_t_us(b_t_ee).apply(&p))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_scale_and_bounds() {
        let p = ProbeModel::LINEAR_38MM;
        let (sx, sy) = p.scale();
        assert!((sx - 0.1).abs() < 1e-6 && (sy - 0.1).abs() < 1e-6);
        assert_eq!(p.pixel_to_image(0.0, 0.0), Some(Vec3::zeros()));
        let q = p.pixel_to_image(384.0, 350.0).unwrap();
        assert!((q - Vec3::new(38.4, 35.0, 0.0)).norm() < 1e-4);
        assert_eq!(p.pixel_to_image(-0.1, 3.0), None);
        assert_eq!(p.pixel_to_image(3.0, 350.5), None);
        assert_eq!(p.pixel_to_image(f32::NAN, 3.0), None);
    }

    #[test]
    fn bad_probe_and_calibration_are_config_errors() {
        let mut p = ProbeModel::LINEAR_38MM;
        p.width_px = 0;
        assert!(matches!(p.validate(), Err(Error::Config(_))));
        p = ProbeModel::LINEAR_38MM;
        p.depth_mm = f32::NAN;
        assert!(matches!(p.validate(), Err(Error::Config(_))));
        let mut c = Calibration::centred(ProbeModel::LINEAR_38MM, Rigid::identity());
        assert_eq!(c.validate(), Ok(()));
        c.ee_t_tcp.rotation[(0, 0)] = 2.0;
        assert!(matches!(c.validate(), Err(Error::Config(_))));
        c = Calibration::centred(ProbeModel::LINEAR_38MM, Rigid::identity());
        c.tcp_t_us.rotation = -Matrix3::identity(); // det −1: a mirror
        assert!(matches!(c.validate(), Err(Error::Config(_))));
    }

    /// Hand-computed: the centred image with an identity holder; flange at (100, 200, 300)
    /// turned 90° about base z. Pixel (192, 100) is the middle column, 10 mm deep: 10 mm
    /// along TCP z, which the flange keeps as base z.
    #[test]
    fn hand_computed_chain() {
        let c = Calibration::centred(ProbeModel::LINEAR_38MM, Rigid::identity());
        let b_t_ee = Rigid {
            rotation: Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0),
            translation: Vec3::new(100.0, 200.0, 300.0),
        };
        let p = c.pixel_to_base(&b_t_ee, 192.0, 100.0).unwrap();
        assert!((p - Vec3::new(100.0, 200.0, 310.0)).norm() < 1e-4, "{p}");
        // Column 0, row 0: −19.2 mm along TCP x, which the flange turns onto base y.
        let p = c.pixel_to_base(&b_t_ee, 0.0, 0.0).unwrap();
        assert!((p - Vec3::new(100.0, 180.8, 300.0)).norm() < 1e-4, "{p}");
        // A 50 mm holder along the flange z moves everything 50 mm along base z.
        let c = Calibration::centred(
            ProbeModel::LINEAR_38MM,
            Rigid {
                rotation: Matrix3::identity(),
                translation: Vec3::new(0.0, 0.0, 50.0),
            },
        );
        let p = c.pixel_to_base(&b_t_ee, 384.0, 350.0).unwrap();
        assert!((p - Vec3::new(100.0, 219.2, 385.0)).norm() < 1e-4, "{p}");
    }
}
