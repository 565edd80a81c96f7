//! Temporal calibration: the lag between the US image stream and the robot tracking
//! stream, from a calibration sweep (the probe moved up and down above a landmark).
//!
//! # Method (paper III-A.2, after Salehi et al. 2017)
//! 1. The tracked TCP positions are projected on their principal axis (the direction the
//!    probe moved along): a scalar signal `s(t)`, mm. The landmark's pixel row `r(t)` is
//!    the video signal. Either too still is refused ([`Error::Swing`]: peak-to-peak below
//!    [`MIN_SWING_MM`] or [`MIN_SWING_PX`]).
//! 2. For a candidate lag `L` (positive: the video lags the tracker), every frame `i` is
//!    paired with the tracker signal linearly interpolated at `t_i − L`; frames whose
//!    shifted time falls outside the tracked range are left out. The score is the
//!    normalised cross-correlation (Pearson) of the pairs. Its sign depends on the axis
//!    direction and on whether the row grows as the probe rises, so both signs are tried:
//!    the search maximises `|NCC|`.
//! 3. Coarse search: one frame period (median frame interval) steps over
//!    ±[`SEARCH_HALF_RANGE_S`]; fine search: [`FINE_STEP_S`] (1 ms) steps within one frame
//!    period of the coarse best; sub-sample refinement: the vertex of the parabola through
//!    the fine best and its two neighbours.
//! 4. At the lag found, the row is fitted to the position by least squares
//!    (`r ≈ a·s + b`); its RMSE (pixels) is the residual reported.
//!
//! Accuracy (README, "Temporal calibration"): on simulated 20 s sweeps at 30 fps with
//! 0.5 px row noise and 1 ms time-stamp jitter the lag is recovered within ±2 ms for lags
//! of 0–400 ms.

use crate::error::{Error, Result, Stream};
use crate::Vec3;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// One tracked TCP position.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackerSample {
    /// Time, s (tracker clock).
    pub t: f64,
    /// TCP position in the base frame, mm.
    pub position: Vec3,
}

/// The landmark's row in one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VideoSample {
    /// Time, s (video clock).
    pub t: f64,
    /// Landmark row, pixels.
    pub row: f32,
}

/// Smallest accepted peak-to-peak motion along the principal axis, mm.
pub const MIN_SWING_MM: f32 = 3.0;
/// Smallest accepted peak-to-peak landmark row change, pixels.
pub const MIN_SWING_PX: f32 = 10.0;
/// Fewest tracker samples accepted (half a second at 100 Hz).
pub const MIN_TRACKER_SAMPLES: usize = 50;
/// Fewest frames accepted, and fewest frame/position pairs a candidate lag must keep.
pub const MIN_VIDEO_SAMPLES: usize = 30;
/// Lags searched: ±0.5 s.
pub const SEARCH_HALF_RANGE_S: f64 = 0.5;
/// Fine search step, s.
pub const FINE_STEP_S: f64 = 1e-3;
/// Smallest |NCC| at the best lag accepted.
pub const MIN_NCC: f32 = 0.5;

/// The lag found and how well it explains the data.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagEstimate {
    /// Lag, s: positive when the video lags the tracker (a frame stamped `t` shows the
    /// probe where the tracker saw it at `t − lag`).
    pub lag_s: f64,
    /// Normalised cross-correlation at the lag (its sign: +1 if the row grows with the
    /// position along the principal axis as oriented here).
    pub ncc: f32,
    /// RMSE of the linear row-from-position fit at the lag, pixels.
    pub rmse_px: f32,
    /// Frame/position pairs used at the lag.
    pub pairs: u32,
    /// Peak-to-peak motion along the principal axis, mm.
    pub swing_mm: f32,
    /// Peak-to-peak landmark row, pixels.
    pub swing_px: f32,
    /// Fitted pixels per mm of motion (the slope `a`).
    pub px_per_mm: f32,
}

/// Estimates the lag of `video` behind `tracker` (see the module docs). Both must have
/// strictly increasing, finite time stamps.
pub fn calibrate(tracker: &[TrackerSample], video: &[VideoSample]) -> Result<LagEstimate> {
    check_stream(
        tracker
            .iter()
            .map(|s| (s.t, s.position.iter().all(|v| v.is_finite()))),
        Stream::Tracker,
        MIN_TRACKER_SAMPLES,
    )?;
    check_stream(
        video.iter().map(|s| (s.t, s.row.is_finite())),
        Stream::Video,
        MIN_VIDEO_SAMPLES,
    )?;
    let signal = AxisSignal::new(tracker);
    let swing_mm = signal.swing() as f32;
    if swing_mm < MIN_SWING_MM {
        return Err(Error::Swing {
            stream: Stream::Tracker,
            found: swing_mm,
            min: MIN_SWING_MM,
        });
    }
    let (lo, hi) = video
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), s| {
            (lo.min(s.row), hi.max(s.row))
        });
    let swing_px = hi - lo;
    if swing_px < MIN_SWING_PX {
        return Err(Error::Swing {
            stream: Stream::Video,
            found: swing_px,
            min: MIN_SWING_PX,
        });
    }

    let period = median_interval(video);
    let score = |lag: f64| pairs_at(&signal, video, lag).score();
    let best_on = |from: f64, to: f64, step: f64| -> (f64, f64) {
        let n = libm::floor((to - from) / step + 1e-9) as i64;
        (0..=n)
            .map(|k| from + k as f64 * step)
            .map(|lag| (lag, score(lag)))
            .fold(
                (from, f64::NEG_INFINITY),
                |a, b| if b.1 > a.1 { b } else { a },
            )
    };
    let (coarse, best) = best_on(-SEARCH_HALF_RANGE_S, SEARCH_HALF_RANGE_S, period);
    if !best.is_finite() {
        return Err(Error::TooFewSamples {
            stream: Stream::Video,
            found: 0,
            min: MIN_VIDEO_SAMPLES as u32,
        });
    }
    let (fine, best) = best_on(coarse - period, coarse + period, FINE_STEP_S);
    // Parabola through (−1, a), (0, b), (+1, c) steps: vertex at (a − c) / (2(a − 2b + c)).
    let (a, c) = (score(fine - FINE_STEP_S), score(fine + FINE_STEP_S));
    let curvature = a - 2.0 * best + c;
    let offset = if a.is_finite() && c.is_finite() && curvature < 0.0 {
        (0.5 * (a - c) / curvature).clamp(-0.5, 0.5)
    } else {
        0.0
    };
    let lag = fine + offset * FINE_STEP_S;

    let pairs = pairs_at(&signal, video, lag);
    if pairs.n < MIN_VIDEO_SAMPLES as f64 {
        return Err(Error::TooFewSamples {
            stream: Stream::Video,
            found: pairs.n as u32,
            min: MIN_VIDEO_SAMPLES as u32,
        });
    }
    let ncc = pairs.ncc() as f32;
    if ncc.abs() < MIN_NCC || !ncc.is_finite() {
        return Err(Error::Correlation {
            found: ncc.abs(),
            min: MIN_NCC,
        });
    }
    let (slope, rmse) = pairs.line_fit();
    Ok(LagEstimate {
        lag_s: lag,
        ncc,
        rmse_px: rmse as f32,
        pairs: pairs.n as u32,
        swing_mm,
        swing_px,
        px_per_mm: slope as f32,
    })
}

/// At least `min` samples, each finite with a time later than the one before.
fn check_stream(
    samples: impl Iterator<Item = (f64, bool)>,
    stream: Stream,
    min: usize,
) -> Result<()> {
    let mut last = f64::NEG_INFINITY;
    let mut n = 0usize;
    for (i, (t, finite)) in samples.enumerate() {
        if !finite || !t.is_finite() || t <= last {
            return Err(Error::Sample {
                stream,
                index: i as u32,
            });
        }
        last = t;
        n += 1;
    }
    if n < min {
        return Err(Error::TooFewSamples {
            stream,
            found: n as u32,
            min: min as u32,
        });
    }
    Ok(())
}

/// Median of up to 63 evenly spread frame intervals, s (the frame clock is regular: a
/// few dropped frames do not move it), clamped to [`FINE_STEP_S`, `SEARCH_HALF_RANGE_S`].
fn median_interval(video: &[VideoSample]) -> f64 {
    let mut dt = [0.0f64; 63];
    let n = video.len().saturating_sub(1);
    let k = n.min(dt.len());
    if k == 0 {
        return FINE_STEP_S;
    }
    for (j, d) in dt.iter_mut().take(k).enumerate() {
        let i = j * n / k;
        *d = video[i + 1].t - video[i].t;
    }
    let dt = &mut dt[..k];
    dt.sort_unstable_by(f64::total_cmp);
    dt[k / 2].clamp(FINE_STEP_S, SEARCH_HALF_RANGE_S)
}

/// The tracker positions projected on their principal axis.
struct AxisSignal<'a> {
    tracker: &'a [TrackerSample],
    mean: Vector3<f64>,
    axis: Vector3<f64>,
}

impl<'a> AxisSignal<'a> {
    fn new(tracker: &'a [TrackerSample]) -> Self {
        let n = tracker.len() as f64;
        let p = |s: &TrackerSample| s.position.cast::<f64>();
        let mean = tracker.iter().map(p).sum::<Vector3<f64>>() / n;
        let cov = tracker
            .iter()
            .map(|s| {
                let d = p(s) - mean;
                d * d.transpose()
            })
            .sum::<Matrix3<f64>>()
            / n;
        let eig = SymmetricEigen::new(cov);
        let axis = eig.eigenvectors.column(eig.eigenvalues.imax()).into_owned();
        AxisSignal {
            tracker,
            mean,
            axis,
        }
    }

    fn value(&self, i: usize) -> f64 {
        (self.tracker[i].position.cast::<f64>() - self.mean).dot(&self.axis)
    }

    fn swing(&self) -> f64 {
        let (lo, hi) = (0..self.tracker.len())
            .map(|i| self.value(i))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            });
        hi - lo
    }

    /// The signal linearly interpolated at `t`, `None` outside the tracked range.
    fn at(&self, t: f64) -> Option<f64> {
        let tr = self.tracker;
        let first = tr.first()?.t;
        let last = tr.last()?.t;
        if !(first..=last).contains(&t) {
            return None;
        }
        // Last sample at or before t.
        let i = tr.partition_point(|s| s.t <= t).saturating_sub(1);
        if i + 1 >= tr.len() {
            return Some(self.value(i));
        }
        let (a, b) = (&tr[i], &tr[i + 1]);
        let w = (t - a.t) / (b.t - a.t);
        Some(self.value(i) * (1.0 - w) + self.value(i + 1) * w)
    }
}

/// Running sums of (position, row) pairs.
#[derive(Default)]
struct Pairs {
    n: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    syy: f64,
    sxy: f64,
}

fn pairs_at(signal: &AxisSignal<'_>, video: &[VideoSample], lag: f64) -> Pairs {
    let mut p = Pairs::default();
    for f in video {
        if let Some(x) = signal.at(f.t - lag) {
            let y = f64::from(f.row);
            p.n += 1.0;
            p.sx += x;
            p.sy += y;
            p.sxx += x * x;
            p.syy += y * y;
            p.sxy += x * y;
        }
    }
    p
}

impl Pairs {
    /// Centred second moments (n·var x, n·var y, n·cov).
    fn moments(&self) -> (f64, f64, f64) {
        let n = self.n;
        (
            self.sxx - self.sx * self.sx / n,
            self.syy - self.sy * self.sy / n,
            self.sxy - self.sx * self.sy / n,
        )
    }

    fn ncc(&self) -> f64 {
        let (vx, vy, c) = self.moments();
        c / libm::sqrt(vx * vy)
    }

    /// |NCC| if enough pairs are left, −∞ otherwise (never chosen).
    fn score(&self) -> f64 {
        if self.n < MIN_VIDEO_SAMPLES as f64 {
            return f64::NEG_INFINITY;
        }
        let r = libm::fabs(self.ncc());
        if r.is_finite() {
            r
        } else {
            f64::NEG_INFINITY
        }
    }

    /// Slope of `row ≈ a·x + b` and the RMSE of that fit.
    fn line_fit(&self) -> (f64, f64) {
        let (vx, vy, c) = self.moments();
        let a = c / vx;
        let sse = (vy - a * c).max(0.0);
        (a, libm::sqrt(sse / self.n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::Rng;

    /// Up-and-down probe motion (three incommensurate sines, never periodic within the
    /// search range) along a tilted axis; the landmark row follows it `lag` later.
    fn sweep(
        lag: f64,
        noise_px: f32,
        amplitude_mm: f64,
    ) -> (std::vec::Vec<TrackerSample>, std::vec::Vec<VideoSample>) {
        let axis = Vector3::new(0.2, -0.1, 1.0).normalize();
        let z = |t: f64| {
            amplitude_mm
                * (0.6 * libm::sin(2.0 * core::f64::consts::PI * 0.23 * t)
                    + 0.3 * libm::sin(2.0 * core::f64::consts::PI * 0.61 * t + 1.0)
                    + 0.1 * libm::sin(2.0 * core::f64::consts::PI * 1.3 * t + 2.0))
        };
        let mut rng = Rng::new(7);
        let tracker = (0..2000)
            .map(|i| {
                let t = f64::from(i) * 0.01;
                let p = Vector3::new(400.0, -100.0, 250.0) + axis * z(t);
                TrackerSample {
                    t,
                    position: p.cast(),
                }
            })
            .collect();
        let video = (0..590)
            .map(|i| {
                let t = 0.2 + f64::from(i) / 30.0;
                let noise = (rng.next_f32() - 0.5) * 2.0 * noise_px;
                VideoSample {
                    t,
                    row: (150.0 - 10.0 * z(t - lag)) as f32 + noise,
                }
            })
            .collect();
        (tracker, video)
    }

    #[test]
    fn recovers_the_lag_both_signs() {
        for lag in [0.0, 0.268, 0.4, -0.12] {
            let (tr, vi) = sweep(lag, 0.5, 8.0);
            let est = calibrate(&tr, &vi).unwrap();
            assert!((est.lag_s - lag).abs() < 1e-3, "{lag}: {est:?}");
            assert!(est.ncc.abs() > 0.99 && est.rmse_px < 0.6, "{est:?}");
            assert!((est.px_per_mm.abs() - 10.0).abs() < 0.1, "{est:?}");
        }
    }

    #[test]
    fn refuses_too_little_motion_and_bad_streams() {
        let (tr, vi) = sweep(0.1, 0.5, 0.5);
        assert!(matches!(
            calibrate(&tr, &vi),
            Err(Error::Swing {
                stream: Stream::Tracker,
                ..
            })
        ));
        let (tr, mut vi) = sweep(0.1, 0.5, 8.0);
        vi.iter_mut().for_each(|v| v.row = 100.0 + v.row * 0.01);
        assert!(matches!(
            calibrate(&tr, &vi),
            Err(Error::Swing {
                stream: Stream::Video,
                ..
            })
        ));
        let (mut tr, vi) = sweep(0.1, 0.5, 8.0);
        tr[10].t = tr[9].t;
        assert_eq!(
            calibrate(&tr, &vi),
            Err(Error::Sample {
                stream: Stream::Tracker,
                index: 10
            })
        );
        let (tr, mut vi) = sweep(0.1, 0.5, 8.0);
        vi[3].row = f32::NAN;
        assert_eq!(
            calibrate(&tr, &vi),
            Err(Error::Sample {
                stream: Stream::Video,
                index: 3
            })
        );
        assert!(matches!(
            calibrate(&tr[..10], &vi),
            Err(Error::TooFewSamples {
                stream: Stream::Tracker,
                found: 10,
                ..
            })
        ));
    }

    #[test]
    fn refuses_an_unrelated_landmark_track() {
        let (tr, mut vi) = sweep(0.1, 0.5, 8.0);
        let mut rng = Rng::new(3);
        vi.iter_mut()
            .for_each(|v| v.row = 100.0 + 40.0 * rng.next_f32());
        assert!(matches!(
            calibrate(&tr, &vi),
            Err(Error::Correlation { .. })
        ));
    }
}
