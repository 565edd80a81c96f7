//! The whole registration: template preparation, target skeleton, endpoint matching and
//! the mapping (local rigid, or the thin-plate spline of [`Mapping::ThinPlate`]).

use crate::config::{Config, Mapping, RibModel};
use crate::error::{Cloud, Error, Result};
use crate::limits::{
    MAX_CLOUD_POINTS, MIN_CLOUD_POINTS, SKELETON_POINTS, SPLINE_POINTS, STERNUM_STATIONS,
};
use crate::math::geom::{nearest, validate, validate_count, validate_points, Frame, Rigid};
use crate::math::spline::{ThinPlate, ThinPlateFit};
use crate::registration::endpoints::{match_endpoints, EndpointMatch};
use crate::registration::guided::{
    check_coverage, check_levels, check_sides, fit_ribs, label_nodes, rib_levels,
    stations_at_attachments, sternum_stations, GuidedStage, NodeLabels, PoseConfidence,
    TargetSkeleton,
};
use crate::registration::local_rigid::{LocalRigid, TransformCache};
use crate::registration::skeleton::{GraphBuild, RibEnds, RibSkeleton, SkeletonGraph};
use crate::Vec3;

/// The prepared CT template: skeleton graph, rib order and the 30 skeleton points.
/// Built once per template (on the host), reused for every patient.
#[derive(Clone, Debug, PartialEq)]
pub struct Template {
    /// SOM / MST / endpoints of the template cloud.
    pub graph: SkeletonGraph,
    /// Label of each SOM-1 node (empty for an unlabelled template).
    pub node_labels: NodeLabels,
    /// Rib order of the template's endpoints (graph model).
    pub ends: Option<RibEnds>,
    /// The 30 skeleton points (paths and degrees are empty for the guided model).
    pub skeleton: RibSkeleton,
    /// Guided model: where the sternum splits each rib, as a fraction of its extent.
    pub midline_fraction: [f32; 4],
}

impl Template {
    /// Prepares a template cloud in the patient frame (x lateral, y cranial, z anterior);
    /// `labels` (one per point: rib number 2..=5, 1 sternum, other values ignored) fix
    /// the rib order when given; the guided model needs them.
    pub fn build(cloud: &[Vec3], labels: Option<&[u8]>, cfg: &Config) -> Result<Self> {
        validate(cloud, Cloud::Template, MIN_CLOUD_POINTS, MAX_CLOUD_POINTS)?;
        let graph = SkeletonGraph::build(cloud, Cloud::Template, cfg, true)?;
        let node_labels = match labels {
            Some(l) => label_nodes(&graph.som1, cloud, l)?,
            None => NodeLabels::new(),
        };
        match cfg.rib_model {
            RibModel::Graph => {
                let ends = RibEnds::from_template(&graph, cloud, labels)?;
                let skeleton = RibSkeleton::build(&graph, &ends, cfg, Cloud::Template)?;
                Ok(Template {
                    graph,
                    node_labels,
                    ends: Some(ends),
                    skeleton,
                    midline_fraction: [0.5; 4],
                })
            }
            RibModel::Guided => {
                if labels.is_none() {
                    return Err(Error::Config(
                        "the guided rib model needs a labelled template",
                    ));
                }
                // Points take their nearest node's label, exactly as the target's will.
                let (points, midline_fraction) = fit_ribs(
                    cloud,
                    &graph.som1,
                    &node_labels,
                    &Rigid::identity(),
                    |_, p| nearest(&graph.som1, p).map_or(0, |(j, _)| node_labels[j]),
                    None,
                    Cloud::Template,
                    cfg.rib_tips,
                )?;
                let skeleton = RibSkeleton {
                    points,
                    paths: Default::default(),
                    degree: [3; 4],
                };
                Ok(Template {
                    graph,
                    node_labels,
                    ends: None,
                    skeleton,
                    midline_fraction,
                })
            }
        }
    }
}

impl Template {
    /// A guided-model template from its compact parts, as the controller receives it
    /// (in chunks over the serial link): the live SOM-1 nodes with their rib labels, the frame of the
    /// template's key points, the 30 rib skeleton points and the sternum split of each
    /// rib. These are all [`register`] reads of a guided template; the graph's key points,
    /// tree and hull are left empty. The parts are validated: 1..=400 finite nodes within
    /// range, one label each, a proper frame, finite skeleton points, fractions in [0, 1].
    pub fn from_parts(
        som1: &[Vec3],
        labels: &[u8],
        frame: Frame,
        skeleton: [Vec3; crate::limits::SKELETON_POINTS],
        midline_fraction: [f32; 4],
    ) -> Result<Template> {
        validate(som1, Cloud::Template, 1, crate::limits::SOM1_CAPACITY)?;
        validate(
            &skeleton,
            Cloud::Template,
            1,
            crate::limits::SKELETON_POINTS,
        )?;
        if labels.len() != som1.len() {
            return Err(Error::LabelCount {
                found: labels.len() as u32,
                expected: som1.len() as u32,
            });
        }
        let proper = crate::math::geom::is_proper_rigid(&Rigid {
            rotation: frame.axes,
            translation: frame.origin,
        });
        if !proper || !frame.spread.iter().all(|v| v.is_finite() && *v >= 0.0) {
            return Err(Error::Config(
                "template frame must be a finite proper rotation",
            ));
        }
        if !midline_fraction.iter().all(|f| (0.0..=1.0).contains(f)) {
            return Err(Error::Config(
                "template sternum split fractions must be in [0, 1]",
            ));
        }
        let capacity = Error::Capacity {
            capacity: crate::limits::SOM1_CAPACITY as u32,
        };
        let nodes = heapless::Vec::from_slice(som1).map_err(|_| capacity)?;
        let node_labels = NodeLabels::from_slice(labels).map_err(|_| capacity)?;
        Ok(Template {
            graph: SkeletonGraph {
                som1: nodes,
                key_points: heapless::Vec::new(),
                tree: crate::math::mst::Tree::default(),
                frame,
                hull: heapless::Vec::new(),
                midline: 0.0,
                endpoints: Err(Error::Config("a template from parts has no endpoint rule")),
            },
            node_labels,
            ends: None,
            skeleton: RibSkeleton {
                points: skeleton,
                paths: Default::default(),
                degree: [3; 4],
            },
            midline_fraction,
        })
    }
}

/// A registration of a template onto one target.
#[derive(Clone, Debug, PartialEq)]
pub struct Registration {
    /// SOM / MST / endpoints of the target cloud.
    pub graph: SkeletonGraph,
    /// Rigid pose target → template found on the way (endpoint ICP or guided ICP).
    pub pose: Rigid,
    /// How the target's endpoints were matched to the template's (graph model).
    pub matching: Option<EndpointMatch>,
    /// The target's 30 skeleton points, paired with the template's.
    pub skeleton: RibSkeleton,
    /// The paper's mapping template → target (Eq. 6); with [`Mapping::ThinPlate`] it
    /// still gives each waypoint its quality figure ([`LocalRigid::residual`]).
    pub map: LocalRigid,
    /// With [`Mapping::ThinPlate`]: the spline through the paired skeletons (and sternum
    /// stations), which then maps the points ([`Registration::map_in_place`]).
    pub spline: Option<ThinPlate>,
    /// With [`Config::sternum_stations`]: the target's sternum stations, paired with the
    /// template's by the spline (`None` where either shows too little sternum).
    pub sternum: Option<[Vec3; STERNUM_STATIONS]>,
    /// Guided model: how clearly the pose hypotheses picked the pose (`None` for the
    /// graph model).
    pub confidence: Option<PoseConfidence>,
    /// Guided model: per rib (2..=5), the [`crate::registration::guided::side_shares`]
    /// `[right, left]` the target's nodes labelled from the rigid pose show, as checked by
    /// [`crate::registration::guided::check_coverage`] (`None` for the graph model).
    pub coverage: Option<[[f32; 2]; 4]>,
    /// Guided model: per rib (2..=5), how far the sweep shows it — its lowest x,
    /// midline and highest x in the frame of [`Registration::pose`]
    /// ([`crate::registration::guided::RibFits::ends`]) — which
    /// [`crate::registration::reach`] checks the waypoints against (`None` for the graph
    /// model).
    pub reach: Option<[(f32, f32, f32); 4]>,
}

impl Registration {
    /// Where the registration takes template point `p`: by [`Registration::spline`]
    /// when there is one, else by the local rigid transform of `p`'s neighbourhood
    /// (`t`, from [`LocalRigid::transform_for`] or its bounded steps).
    pub fn carry(&self, p: &Vec3, t: &Rigid) -> Vec3 {
        match &self.spline {
            Some(s) => s.apply(p),
            None => t.apply(p),
        }
    }

    /// Maps template points in place (any number: nothing is buffered), by the
    /// configuration's [`Mapping`]. All points are checked first, so on bad input
    /// nothing is changed.
    pub fn map_in_place<const CAP: usize>(
        &self,
        points: &mut [Vec3],
        cache: &mut TransformCache<CAP>,
    ) -> Result<()> {
        match &self.spline {
            Some(s) => {
                validate(points, Cloud::Query, 0, usize::MAX)?;
                for p in points {
                    *p = s.apply(p);
                }
                Ok(())
            }
            None => self.map.map_in_place(points, cache),
        }
    }
}

/// Registers `template` onto the `target` cloud (any pose: no initial alignment needed).
/// Map points through the result with [`Registration::map_in_place`].
pub fn register(template: &Template, target: &[Vec3], cfg: &Config) -> Result<Registration> {
    let mut r = Registering::start(target, cfg)?;
    while !r.step(template, target, cfg, u32::MAX)? {}
    r.into_registration()
        .ok_or(Error::Config("the registration did not finish"))
}

/// Target points checked (finite, in range) per unit of [`Registering::step`]'s budget:
/// a point's six comparisons are a few dozen instructions, a SOM iteration's 400
/// distances some thousands.
pub const CHECK_POINTS_PER_UNIT: usize = 128;

/// A registration in progress, for callers that must bound the work per call (the
/// controller's 100 Hz loop): every [`Registering::step`] does at most `budget` units of
/// work — a unit is [`CHECK_POINTS_PER_UNIT`] target points checked, one SOM iteration, one nearest-neighbour scan of a node set (the
/// dead-unit scans) or about as much work in the guided model (k-d tree queries for ICP
/// pairings, labels and rib-fit points, tree building, neighbourhood widening, see
/// [`TargetSkeleton`]), or one rigid fit — and a stage change is a call of its own. The
/// graph model's endpoint matching and the mapping's set-up take one call each. The
/// result equals [`register`]'s and is kept inside (nothing of kilobytes passes through
/// the caller's stack).
#[derive(Clone)]
pub struct Registering {
    stage: Stage,
    /// With [`Mapping::ThinPlate`]: the spline's system is set up by the next step.
    spline_next: bool,
}

// The stages are exclusive and live once per registration: boxing is not an option
// without a heap, and the size is the largest stage's anyway.
#[allow(clippy::large_enum_variant)]
#[derive(Clone)]
enum Stage {
    /// The target's points before this index are checked finite and in range.
    Check(usize),
    /// The target is checked; its principal axes and initial SOM 1 are next.
    Axes,
    Graph(GraphBuild),
    Guided(SkeletonGraph, TargetSkeleton),
    /// The registration; with [`Mapping::ThinPlate`] its spline is solved in the
    /// second field, in place, before it is done (the variant stays smaller than
    /// `Guided`, so the spline adds nothing to the registration's state).
    Done(Registration, ThinPlateFit),
    Failed,
}

impl Registering {
    /// Checks the target's point count (O(1)); its points are checked, and its SOM 1
    /// prepared (principal axes, initial map), by the first steps — a cloud the size of
    /// [`MAX_CLOUD_POINTS`] is more than one controller call can check.
    pub fn start(target: &[Vec3], _cfg: &Config) -> Result<Self> {
        validate_count(
            target.len(),
            Cloud::Target,
            MIN_CLOUD_POINTS,
            MAX_CLOUD_POINTS,
        )?;
        Ok(Registering {
            stage: Stage::Check(0),
            spline_next: false,
        })
    }

    /// SOM iterations done and in all.
    pub fn progress(&self, cfg: &Config) -> (u32, u32) {
        match &self.stage {
            Stage::Graph(g) => g.progress(cfg),
            Stage::Check(_) | Stage::Axes => (0, cfg.som1.iterations + cfg.som2.iterations),
            _ => {
                let total = cfg.som1.iterations + cfg.som2.iterations;
                (total, total)
            }
        }
    }

    /// What the next step works on: `"check"` (the target's points), `"axes"` (its
    /// principal axes and initial SOM 1), the skeleton graph's stage ([`GraphBuild::stage`]),
    /// then for the guided model
    /// `"index"`, `"coarse"`, `"refine"`, `"label"`, `"fit"`, `"solve"`, `"refit"`, `"carry"`,
    /// then `"spline"` ([`Mapping::ThinPlate`]) and `"done"` (or `"failed"`). For cost
    /// reports.
    pub fn stage(&self) -> &'static str {
        match &self.stage {
            Stage::Check(_) => "check",
            Stage::Axes => "axes",
            Stage::Graph(build) => build.stage(),
            Stage::Guided(_, t) => match t.stage() {
                GuidedStage::Index => "index",
                GuidedStage::Coarse => "coarse",
                GuidedStage::Refine => "refine",
                GuidedStage::Label(_) => "label",
                GuidedStage::Fit(_) => "fit",
                GuidedStage::Solve(_) => "solve",
                GuidedStage::Refit(_) => "refit",
                GuidedStage::Carry(_) => "carry",
                GuidedStage::Support => "support",
                GuidedStage::Done => "map",
            },
            Stage::Done(_, fit) if self.spline_next || fit.solving() => "spline",
            Stage::Done(..) => "done",
            Stage::Failed => "failed",
        }
    }

    /// One bounded step; `true` when the registration is done
    /// ([`Registering::registration`]). `template`, `target` and `cfg` must be those of
    /// every call.
    #[inline(never)]
    pub fn step(
        &mut self,
        template: &Template,
        target: &[Vec3],
        cfg: &Config,
        budget: u32,
    ) -> Result<bool> {
        let outcome = self.advance(template, target, cfg, budget);
        if outcome.is_err() {
            self.stage = Stage::Failed;
        }
        outcome
    }

    // Each stage change is a function of its own (`inline(never)`): their large locals
    // (graph, guided state, registration: 7–16 KiB each) then never share one frame,
    // which overflowed the controller's stack.
    fn advance(
        &mut self,
        template: &Template,
        target: &[Vec3],
        cfg: &Config,
        budget: u32,
    ) -> Result<bool> {
        match &mut self.stage {
            Stage::Check(next) => {
                let end = next
                    .saturating_add((budget as usize).saturating_mul(CHECK_POINTS_PER_UNIT))
                    .min(target.len());
                let chunk = target
                    .get(*next..end)
                    .ok_or(Error::Config("the target changed between steps"))?;
                validate_points(chunk, Cloud::Target, *next)?;
                // The principal axes are a call of their own.
                *next = end;
                if end == target.len() {
                    self.stage = Stage::Axes;
                }
                Ok(false)
            }
            Stage::Axes => self.checked(target, cfg),
            Stage::Graph(build) => {
                // The stage change after the graph is built is a call of its own.
                let built = build.graph().is_some();
                if !build.step(target, cfg, budget)? || !built {
                    return Ok(false);
                }
                self.graph_done(template, cfg)
            }
            Stage::Guided(graph, run) => {
                if !run.step(
                    target,
                    graph,
                    &template.graph,
                    &template.node_labels,
                    &template.skeleton.points,
                    &template.midline_fraction,
                    cfg,
                    budget,
                )? {
                    return Ok(false);
                }
                self.guided_done(template, cfg)?;
                Ok(!self.spline_next)
            }
            Stage::Done(reg, fit) => {
                if self.spline_next {
                    self.spline_next = false;
                    let (source, target, n) = spline_pairs(template, reg);
                    fit.start(&source[..n], &target[..n])?;
                    return Ok(false);
                }
                if !fit.solving() {
                    return Ok(true);
                }
                let columns = (budget as usize).div_ceil(SPLINE_UNITS_PER_COLUMN);
                let Some(spline) = fit.step(columns)? else {
                    return Ok(false);
                };
                reg.spline = Some(spline);
                Ok(true)
            }
            Stage::Failed => Err(Error::Config("the registration failed before")),
        }
    }

    /// The target is checked: its principal axes and initial SOM 1.
    #[inline(never)]
    fn checked(&mut self, target: &[Vec3], cfg: &Config) -> Result<bool> {
        self.stage = Stage::Graph(GraphBuild::start(target, Cloud::Target, cfg, false)?);
        Ok(false)
    }

    /// The skeleton graph is built: the guided stage starts, or (graph model) the
    /// endpoint matching and mapping finish the registration.
    #[inline(never)]
    fn graph_done(&mut self, template: &Template, cfg: &Config) -> Result<bool> {
        let Stage::Graph(build) = &mut self.stage else {
            return Err(Error::Config("the skeleton graph build did not finish"));
        };
        let graph = build
            .take_graph()
            .ok_or(Error::Config("the skeleton graph build did not finish"))?;
        if let (RibModel::Guided, None) = (cfg.rib_model, &template.ends) {
            self.start_guided(graph, template, cfg)?;
            return Ok(false);
        }
        self.finish_graph(graph, template, cfg)?;
        Ok(!self.spline_next)
    }

    /// The guided stage starts on `graph`. A function of its own, like
    /// [`Registering::finish_graph`], so that the stack frame of the one does not add to
    /// the other's in [`Registering::graph_done`] (together they outgrew the controller's
    /// stack once the run's state grew by two pose hypotheses).
    #[inline(never)]
    fn start_guided(
        &mut self,
        graph: SkeletonGraph,
        template: &Template,
        cfg: &Config,
    ) -> Result<()> {
        // The run (~13 KiB) is started in place, not built on the stack and moved.
        self.stage = Stage::Guided(graph, TargetSkeleton::new());
        if let Stage::Guided(graph, run) = &mut self.stage {
            run.start(graph, &template.graph, &template.node_labels, cfg.target_up)?;
        }
        Ok(())
    }

    /// The graph model's endpoint matching and mapping finish the registration.
    #[inline(never)]
    fn finish_graph(
        &mut self,
        graph: SkeletonGraph,
        template: &Template,
        cfg: &Config,
    ) -> Result<()> {
        let (pose, matching, skeleton) = graph_skeleton(template, &graph, cfg)?;
        let registration = finish(template, graph, pose, matching, skeleton, cfg)?;
        self.spline_next = cfg.mapping == Mapping::ThinPlate;
        self.stage = Stage::Done(registration, ThinPlateFit::IDLE);
        Ok(())
    }

    /// The guided target skeleton is done: the mapping finishes the registration.
    #[inline(never)]
    fn guided_done(&mut self, template: &Template, cfg: &Config) -> Result<()> {
        let Stage::Guided(graph, run) = &mut self.stage else {
            return Err(Error::Config("the guided rib model did not finish"));
        };
        let (pose, points) = run.result().ok_or(Error::RigidFit)?;
        let coverage = run.coverage().ok_or(Error::RigidFit)?;
        let confidence = run.confidence();
        // A sweep that misses a side or a rib is refused, not mapped from the wrong
        // cartilage, and so is a pose that a distinct one fits nearly as well, unless
        // the sweep supports the whole template closely; then one that stops short on
        // one side, however well it fits what it shows (after the others, whose
        // messages say more where both apply).
        match confidence {
            Some(c) => c.check(&coverage)?,
            None => check_coverage(&coverage)?,
        }
        check_sides(&coverage)?;
        let levels = rib_levels(
            &points,
            &pose,
            &template.skeleton.points,
            &template.midline_fraction,
        );
        check_levels(&levels)?;
        let skeleton = RibSkeleton {
            points,
            paths: Default::default(),
            degree: [3; 4],
        };
        let sternum = run.sternum().filter(|_| cfg.sternum_stations);
        let graph = core::mem::replace(graph, SkeletonGraph::empty());
        let mut registration = finish(template, graph, pose, None, skeleton, cfg)?;
        registration.confidence = confidence;
        registration.coverage = Some(coverage);
        registration.reach = run.reach();
        registration.sternum = sternum;
        self.spline_next = cfg.mapping == Mapping::ThinPlate;
        self.stage = Stage::Done(registration, ThinPlateFit::IDLE);
        Ok(())
    }

    /// The registration, once done.
    pub fn registration(&self) -> Option<&Registration> {
        match &self.stage {
            Stage::Done(r, fit) if !self.spline_next && !fit.solving() => Some(r),
            _ => None,
        }
    }

    /// The registration, once done.
    pub fn into_registration(self) -> Option<Registration> {
        match self.stage {
            Stage::Done(r, fit) if !self.spline_next && !fit.solving() => Some(r),
            _ => None,
        }
    }
}

/// The graph model's target skeleton: endpoint matching and tree paths.
#[inline(never)]
fn graph_skeleton(
    template: &Template,
    graph: &SkeletonGraph,
    cfg: &Config,
) -> Result<(Rigid, Option<EndpointMatch>, RibSkeleton)> {
    match (cfg.rib_model, &template.ends) {
        (RibModel::Graph, Some(ends)) => {
            let matching = match_endpoints(graph, &template.graph, ends)?;
            let skeleton = RibSkeleton::build(graph, &matching.ends, cfg, Cloud::Target)?;
            Ok((matching.pose, Some(matching), skeleton))
        }
        _ => Err(Error::Config(
            "template and registration use different rib models",
        )),
    }
}

/// Units of [`Registering::step`]'s budget per column of the thin-plate spline's system
/// eliminated: a column is at most 37 · 41 multiply-adds, about two SOM iterations'
/// work (with one unit a column, eight columns took a controller call to 174,600
/// instructions, over its 168,000).
pub const SPLINE_UNITS_PER_COLUMN: usize = 2;

/// The thin-plate spline's pairs of `reg` (of `template`): the skeleton points, and the
/// sternum stations when both clouds have them; the count in use.
fn spline_pairs(
    template: &Template,
    reg: &Registration,
) -> ([Vec3; SPLINE_POINTS], [Vec3; SPLINE_POINTS], usize) {
    let mut source = [Vec3::zeros(); SPLINE_POINTS];
    let mut target = [Vec3::zeros(); SPLINE_POINTS];
    source[..SKELETON_POINTS].copy_from_slice(&template.skeleton.points);
    target[..SKELETON_POINTS].copy_from_slice(&reg.skeleton.points);
    let own = sternum_stations(
        &template.graph.som1,
        &template.node_labels,
        &Rigid::identity(),
    );
    match (own, reg.sternum) {
        (Some(s), Some(t)) => {
            let (s, t) = stations_at_attachments(
                &s,
                &template.skeleton.points,
                &t,
                &reg.skeleton.points,
                &template.midline_fraction,
            );
            source[SKELETON_POINTS..].copy_from_slice(&s);
            target[SKELETON_POINTS..].copy_from_slice(&t);
            (source, target, SPLINE_POINTS)
        }
        _ => (source, target, SKELETON_POINTS),
    }
}

/// The mapping template → target from the paired skeletons (the spline, if any, is
/// solved after).
fn finish(
    template: &Template,
    graph: SkeletonGraph,
    pose: Rigid,
    matching: Option<EndpointMatch>,
    skeleton: RibSkeleton,
    cfg: &Config,
) -> Result<Registration> {
    let map = LocalRigid::new(template.skeleton.points, skeleton.points, cfg.neighbours)?;
    Ok(Registration {
        graph,
        pose,
        matching,
        skeleton,
        map,
        spline: None,
        sternum: None,
        confidence: None,
        coverage: None,
        reach: None,
    })
}
