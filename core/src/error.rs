//! The one error type of the core: small, `Copy`, and specific about what was found and
//! what was expected.

use core::fmt;

/// Which cloud an error is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Cloud {
    /// The CT template cloud (source).
    Template,
    /// The US target cloud.
    Target,
    /// Points handed to the mapping (waypoints or any other cloud).
    Query,
}

/// Which time-stamped input stream an error is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Stream {
    /// Tracked probe positions of a temporal-calibration sweep.
    Tracker,
    /// Landmark rows of a temporal-calibration sweep.
    Video,
    /// Robot poses of a scanning sweep.
    Poses,
    /// Annotated US frames of a scanning sweep.
    Frames,
}

/// A side of the patient, in ribreg's patient frame (x toward the patient's left).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Side {
    /// The patient's left, +x.
    Left,
    /// The patient's right, −x.
    Right,
}

impl Side {
    /// `"left"` or `"right"` (reports; `Display` adds the axis).
    pub fn name(self) -> &'static str {
        match self {
            Side::Left => "left",
            Side::Right => "right",
        }
    }
}

/// Everything that can go wrong in the core. Every variant names what was found and,
/// where it applies, what was expected.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error {
    /// A cloud has fewer points than the pipeline needs.
    TooFewPoints {
        /// Which cloud.
        cloud: Cloud,
        /// Points found.
        found: u32,
        /// Minimum accepted.
        min: u32,
    },
    /// A cloud has more points than the core can index.
    TooManyPoints {
        /// Which cloud.
        cloud: Cloud,
        /// Points found.
        found: u32,
        /// Maximum accepted.
        max: u32,
    },
    /// A coordinate is NaN or infinite.
    NonFinite {
        /// Which cloud.
        cloud: Cloud,
        /// Index of the offending point.
        index: u32,
    },
    /// A coordinate is beyond [`crate::limits::MAX_COORD_MM`] in magnitude.
    OutOfRange {
        /// Which cloud.
        cloud: Cloud,
        /// Index of the offending point.
        index: u32,
    },
    /// The cloud has no 2-D extent (all points equal or on a line): no skeleton exists.
    Degenerate {
        /// Which cloud.
        cloud: Cloud,
        /// Second largest spread (standard deviation along the second principal axis), mm.
        spread_mm: f32,
    },
    /// The label slice does not have one label per point.
    LabelCount {
        /// Labels given.
        found: u32,
        /// Points in the cloud.
        expected: u32,
    },
    /// The skeleton tree does not show the rib endpoints the method needs on one side
    /// of the sternum.
    Endpoints {
        /// Which cloud.
        cloud: Cloud,
        /// Side (0 = negative first principal axis, 1 = positive).
        side: u8,
        /// Endpoint candidates found on that side.
        found: u8,
        /// Endpoints needed per side (one per rib).
        expected: u8,
    },
    /// The template's rib labels do not give each rib 2..5 exactly one endpoint (or, in
    /// the guided model, at least one node) per side.
    RibOrder {
        /// Side (0 or 1).
        side: u8,
        /// The rib number (2..=5) that is missing or repeated.
        rib: u8,
        /// Endpoints (guided model: nodes) carrying that rib's label on that side.
        found: u8,
    },
    /// Too few points are left on a rib (its tree path after the turn filter, or its
    /// labelled nodes in the guided model) to fit its curve.
    RibPath {
        /// Which cloud.
        cloud: Cloud,
        /// Rib number 2..=5.
        rib: u8,
        /// Points found for the rib.
        found: u8,
        /// Minimum needed (a line needs 2).
        min: u8,
    },
    /// A rigid fit had no solution (coincident points) or failed its accuracy check.
    RigidFit,
    /// A fixed-capacity buffer is full; nothing was written past it.
    Capacity {
        /// The capacity that was reached.
        capacity: u32,
    },
    /// A configuration value is out of its valid range.
    Config(&'static str),
    /// A stream has fewer samples than the computation needs.
    TooFewSamples {
        /// Which stream.
        stream: Stream,
        /// Samples found (for a lag search: the pairs left after the shift).
        found: u32,
        /// Minimum needed.
        min: u32,
    },
    /// A sample has a NaN/infinite value, a value out of range (a coordinate beyond
    /// [`crate::limits::MAX_COORD_MM`], a pose's quaternion further than
    /// [`crate::acquisition::track::QUATERNION_NORM_TOLERANCE`] from unit norm) or a time
    /// stamp not later than the one before.
    Sample {
        /// Which stream.
        stream: Stream,
        /// Index of the offending sample.
        index: u32,
    },
    /// A calibration sweep moves too little to calibrate: its swing (peak to peak along
    /// the motion's principal axis, mm, or of the landmark row, pixels) is below the minimum.
    Swing {
        /// Which stream is too still.
        stream: Stream,
        /// Swing found (mm for the tracker, pixels for the video).
        found: f32,
        /// Minimum accepted.
        min: f32,
    },
    /// The best lag correlates the two signals too weakly to be trusted.
    Correlation {
        /// |normalised cross-correlation| at the best lag.
        found: f32,
        /// Minimum accepted.
        min: f32,
    },
    /// A time is outside the tracked time range: poses are interpolated, never
    /// extrapolated.
    OutsideTrack {
        /// How far outside, ms: negative before the oldest pose kept, positive after the
        /// newest (0 if no pose has been received).
        by_ms: f32,
    },
    /// Two consecutive tracked poses are too far apart in time to interpolate between.
    TrackGap {
        /// The gap, ms.
        gap_ms: f32,
        /// Largest gap interpolated over, ms.
        max_ms: f32,
    },
    /// An annotated pixel is outside the image or not finite.
    Pixel {
        /// Index of the offending pixel in its frame.
        index: u32,
    },
    /// The target does not show one side of a rib: the rib's fitted curve spans too
    /// little of the template's on that side (guided model; see
    /// [`crate::registration::guided::check_coverage`]). A sweep that missed a side or a
    /// rib; a registration from it would carry waypoints there from the wrong cartilage.
    NotSeen {
        /// Rib number 2..=5.
        rib: u8,
        /// The side.
        side: Side,
        /// Span of the target's rib on that side, percent of the template's.
        percent: u8,
        /// Least accepted, percent.
        min_percent: u8,
    },
    /// No pose hypothesis agrees with the target's up prior
    /// ([`crate::config::Config::target_up`]): the closest turned it this far from the
    /// template's anterior axis.
    AgainstPrior {
        /// The closest hypothesis's angle, degrees.
        closest_deg: u8,
        /// The largest accepted, degrees.
        cone_deg: u8,
    },
    /// The target's pose is not clear (guided model; see
    /// [`crate::registration::guided::PoseConfidence::check`]): the best pose hypothesis
    /// fits too loosely, or a distinct one fits nearly as well. A sweep of something else,
    /// or a chest so symmetric in what was scanned that a flip cannot be ruled out.
    Ambiguous {
        /// Residual of the best pose, tenths of a mm.
        residual_dmm: u16,
        /// Residual of the best distinct pose, tenths of a mm (saturated when none).
        runner_up_dmm: u16,
        /// Largest accepted residual, tenths of a mm.
        max_residual_dmm: u16,
        /// Least accepted runner-up residual, percent of the best's.
        min_margin_percent: u8,
    },
    /// The sweep does not support the mapped template (guided model; see
    /// [`crate::registration::guided::MAX_CHECKED_SUPPORT_MM`]): its nodes, carried into
    /// the target, lie this far from the sweep's (RMS). A sweep that missed part of the
    /// chest, or a registration that carried the template beside it.
    Unsupported {
        /// [`crate::registration::guided::PoseConfidence::support_mm`], tenths of a mm
        /// (saturated; 0 when not measured).
        support_dmm: u16,
        /// Largest accepted, tenths of a mm.
        max_support_dmm: u16,
    },
    /// One side of the target looks cut short by the sweep (guided model; see
    /// [`crate::registration::guided::check_sides`]): its ribs span much less of the
    /// template's than the other side's. A registration would squeeze the template's
    /// ribs onto what is there and pull that side's waypoints toward the sternum.
    SideShort {
        /// The short side.
        side: Side,
        /// Mean span of its ribs, percent of the template's.
        percent: u8,
        /// The same on the other side.
        other_percent: u8,
        /// Least accepted ratio of the two, percent.
        min_ratio_percent: u8,
    },
    /// Both sides of the target look cut short by the sweep (guided model; see
    /// [`crate::registration::guided::MIN_MEAN_SHARE`]): its ribs span much less of the
    /// template's on average than any complete sweep does. A registration would squeeze
    /// the template's ribs onto what is there and pull every lateral waypoint toward the
    /// sternum.
    SweepShort {
        /// The ribs measured: from this rib (2 or 4) to rib 5, both sides.
        from_rib: u8,
        /// Mean span of those rib sides in the target, percent of the template's.
        percent: u8,
        /// Least accepted, percent.
        min_percent: u8,
    },
    /// The sweep does not show a waypoint's gap as far out as the waypoint lies (guided
    /// model; see [`crate::registration::reach`]): a sweep hole or a lost lateral tip
    /// took a bounding cartilage there, and the waypoint would be placed by the
    /// template's shape alone.
    NotReached {
        /// The waypoint, 0-based (saturated).
        waypoint: u8,
        /// The bounding rib, 2..=5.
        rib: u8,
        /// The side.
        side: Side,
        /// How far beyond that rib's observed end the waypoint lies, tenths of a mm
        /// (saturated: a rib not seen).
        beyond_dmm: u16,
        /// Largest accepted, tenths of a mm.
        max_beyond_dmm: u16,
    },
    /// A rib end the sweep shows lies at the edge of what the probe imaged (guided model
    /// with the sweep's imaged area; see [`crate::registration::reach::check_edges`]):
    /// the sweep may have stopped short of that cartilage, and the registration would
    /// squeeze the template's rib onto what it shows.
    SweepEdge {
        /// The rib, 2..=5.
        rib: u8,
        /// The side.
        side: Side,
        /// How far beyond the rib's end the sweep imaged, tenths of a mm.
        clearance_dmm: u16,
        /// Least accepted, tenths of a mm.
        min_dmm: u16,
    },
    /// A rib's two sides meet the sternum at different heights in the target (guided
    /// model; see [`crate::registration::guided::check_levels`]): cartilages join the
    /// sternum in pairs at one level, so the registration took one side's cartilages for
    /// the next rib's, and that side's waypoints would land a gap off.
    RibLevels {
        /// Rib number 2..=5.
        rib: u8,
        /// How far apart in height its two sides meet the sternum, against the
        /// template's, tenths of a mm (saturated).
        step_dmm: u16,
        /// Largest accepted, tenths of a mm.
        max_dmm: u16,
    },
}

impl fmt::Display for Cloud {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Cloud::Template => "template",
            Cloud::Target => "target",
            Cloud::Query => "query",
        })
    }
}

impl fmt::Display for Side {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Side::Left => "left (+x)",
            Side::Right => "right (−x)",
        })
    }
}

impl fmt::Display for Stream {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Stream::Tracker => "tracker",
            Stream::Video => "video",
            Stream::Poses => "pose",
            Stream::Frames => "frame",
        })
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Error::TooFewPoints { cloud, found, min } => {
                write!(f, "{cloud} cloud has {found} points, at least {min} are needed")
            }
            Error::TooManyPoints { cloud, found, max } => {
                write!(f, "{cloud} cloud has {found} points, at most {max} are accepted")
            }
            Error::NonFinite { cloud, index } => {
                write!(f, "{cloud} point {index} has a NaN or infinite coordinate")
            }
            Error::OutOfRange { cloud, index } => write!(
                f,
                "{cloud} point {index} has a coordinate beyond ±{} mm",
                crate::limits::MAX_COORD_MM
            ),
            Error::Degenerate { cloud, spread_mm } => write!(
                f,
                "{cloud} cloud is degenerate: spread along its second axis is {spread_mm} mm, \
                 a rib cage needs a 2-D extent"
            ),
            Error::LabelCount { found, expected } => {
                write!(f, "{found} labels given for {expected} points")
            }
            Error::Endpoints { cloud, side, found, expected } => write!(
                f,
                "{cloud} skeleton shows {found} rib endpoints on side {side}, expected {expected} \
                 (one per rib 2..5)"
            ),
            Error::RibOrder { side, rib, found } => write!(
                f,
                "template labels give rib {rib} {found} endpoints on side {side}, expected exactly 1 \
                 (are ribs 2..5 all labelled on both sides?)"
            ),
            Error::RibPath { cloud, rib, found, min } => write!(
                f,
                "{cloud} rib {rib}: {found} skeleton points found, at least {min} are needed \
                 to fit its curve (is rib {rib} in the cloud, labelled and seen on both sides?)"
            ),
            Error::RigidFit => f.write_str(
                "rigid fit failed: the point set is degenerate or the SVD failed its check",
            ),
            Error::Capacity { capacity } => write!(f, "buffer full at its capacity of {capacity}"),
            Error::Config(what) => write!(f, "invalid configuration: {what}"),
            Error::TooFewSamples { stream, found, min } => {
                write!(f, "{stream} stream has {found} samples, at least {min} are needed")
            }
            Error::Sample { stream, index } => write!(
                f,
                "{stream} sample {index} is not finite, out of range (a coordinate, or a \
                 quaternion off unit norm) or not later than the sample before it"
            ),
            Error::Swing { stream, found, min } => {
                let unit = if stream == Stream::Video { "px" } else { "mm" };
                write!(
                    f,
                    "the calibration sweep moves too little: {stream} swing {found:.2} {unit}, \
                     at least {min} {unit} needed (move the probe further up and down)"
                )
            }
            Error::Correlation { found, min } => write!(
                f,
                "the landmark track follows the probe motion too weakly at any lag \
                 (|NCC| {found:.3}, at least {min} needed): is the landmark tracked?"
            ),
            Error::OutsideTrack { by_ms } => {
                if by_ms < 0.0 {
                    write!(f, "time is {:.1} ms before the oldest tracked pose", -by_ms)
                } else if by_ms > 0.0 {
                    write!(f, "time is {by_ms:.1} ms after the newest tracked pose")
                } else {
                    f.write_str("no tracked pose yet")
                }
            }
            Error::TrackGap { gap_ms, max_ms } => write!(
                f,
                "tracked poses are {gap_ms:.1} ms apart here, at most {max_ms} ms is interpolated"
            ),
            Error::Pixel { index } => {
                write!(f, "pixel {index} of the frame is outside the image or not finite")
            }
            Error::NotSeen { rib, side, percent, min_percent } => write!(
                f,
                "rib {rib} not seen on the patient's {side}: the target's rib spans {percent} % \
                 of the template's there, at least {min_percent} % is needed (did the sweep \
                 miss that side or that rib? scan it and register again)"
            ),
            Error::AgainstPrior { closest_deg, cone_deg } => write!(
                f,
                "no pose of the target agrees with its up prior: the closest turns it \
                 {closest_deg}° from the patient's anterior, at most {cone_deg}° accepted (is the \
                 prior right? register without it)"
            ),
            Error::Ambiguous {
                residual_dmm,
                runner_up_dmm,
                max_residual_dmm,
                min_margin_percent,
            } => {
                let mm = |d: u16| f32::from(d) / 10.0;
                write!(
                    f,
                    "the target's pose is ambiguous: the best pose hypothesis fits with {:.1} mm \
                     residual (at most {:.1} mm accepted) and ",
                    mm(residual_dmm),
                    mm(max_residual_dmm),
                )?;
                // A saturated runner-up is none (or one beyond 6,553 mm): no number.
                if runner_up_dmm == u16::MAX {
                    write!(f, "no distinct one was found to compare it with")?;
                } else {
                    write!(
                        f,
                        "the next distinct one with {:.1} mm (at least {min_margin_percent} % \
                         of the best's needed)",
                        mm(runner_up_dmm),
                    )?;
                }
                write!(
                    f,
                    "; is the sweep of the rib cartilage? scan more of both sides and register \
                     again"
                )
            }
            Error::SideShort {
                side,
                percent,
                other_percent,
                min_ratio_percent,
            } => write!(
                f,
                "the sweep looks cut short on the patient's {side}: its ribs span {percent} % \
                 of the template's there against {other_percent} % on the other side (at least \
                 {min_ratio_percent} % of the other side's is needed); scan that side out to the \
                 ends of the cartilages and register again"
            ),
            Error::SweepShort {
                from_rib,
                percent,
                min_percent,
            } => {
                f.write_str("the sweep looks cut short on both sides: ")?;
                if from_rib <= 2 {
                    f.write_str("the ribs span")?;
                } else {
                    write!(f, "ribs {from_rib}–5 span")?;
                }
                write!(
                    f,
                    " {percent} % of the template's on average (at least {min_percent} % is \
                     needed); scan both sides out to the ends of the cartilages and register \
                     again, or use a template whose cartilages are not much longer than the \
                     patient's"
                )
            }
            Error::NotReached {
                waypoint,
                rib,
                side,
                beyond_dmm,
                max_beyond_dmm,
            } => {
                let mm = |d: u16| f32::from(d) / 10.0;
                write!(f, "waypoint {} is not reached by the sweep: ", u16::from(waypoint) + 1)?;
                if beyond_dmm == u16::MAX {
                    write!(f, "rib {rib} is not seen on the patient's {side}")?;
                } else {
                    write!(
                        f,
                        "it lies {:.1} mm beyond the end of rib {rib} the sweep shows on the \
                         patient's {side} (at most {:.1} mm accepted)",
                        mm(beyond_dmm),
                        mm(max_beyond_dmm)
                    )?;
                }
                f.write_str(
                    "; scan that cartilage out to its lateral end and register again, or map \
                     only the waypoints the sweep reaches (a partial plan)",
                )
            }
            Error::SweepEdge {
                rib,
                side,
                clearance_dmm,
                min_dmm,
            } => {
                let mm = |d: u16| f32::from(d) / 10.0;
                write!(
                    f,
                    "rib {rib} runs to the edge of the sweep on the patient's {side}: the probe \
                     imaged {:.1} mm beyond the end the sweep shows (at least {:.1} mm is \
                     needed), so the cartilage may go on; scan that side past the cartilages' \
                     ends and register again, or map only the other side (a partial plan)",
                    mm(clearance_dmm),
                    mm(min_dmm)
                )
            }
            Error::RibLevels { rib, step_dmm, max_dmm } => {
                let mm = |d: u16| f32::from(d) / 10.0;
                write!(
                    f,
                    "rib {rib}'s two sides meet the sternum {:.1} mm apart in height, against \
                     the template's (at most {:.1} mm accepted): the registration took one \
                     side's cartilages for the next rib's; scan both sides, ribs 2 to 5, from \
                     the sternum out and register again",
                    mm(step_dmm),
                    mm(max_dmm)
                )
            }
            Error::Unsupported {
                support_dmm,
                max_support_dmm,
            } => {
                let mm = |d: u16| f32::from(d) / 10.0;
                f.write_str("the sweep does not support the mapped template: ")?;
                // Only an unmeasured support is 0 here (a measured 0 is within any bound).
                if support_dmm == 0 {
                    f.write_str("its support was not measured")?;
                } else {
                    write!(f, "its nodes lie {:.1} mm from the sweep's", mm(support_dmm))?;
                }
                write!(
                    f,
                    " (RMS, at most {:.1} mm accepted); did the sweep miss part of the chest? \
                     scan both sides, ribs 2 to 5, and register again",
                    mm(max_support_dmm)
                )
            }
        }
    }
}

impl core::error::Error for Error {}

/// Result with the core's [`Error`].
pub type Result<T> = core::result::Result<T, Error>;
