//! `ribreg.register`, `ribreg.Template`, `ribreg.Registration`, `ribreg.read_cloud` and
//! `ribreg.read_waypoints`: the CLI's `register` and readers with numpy arrays.
//!
//! # Contract
//! * Arrays: any array-like of shape (N, 3) and any real dtype or memory order (numpy's
//!   `asarray` casts to float64; the core computes in f32, as the CLI does). Results are
//!   new C-ordered float64 arrays.
//! * Same numbers as the CLI: every call goes through the functions `ribreg register`
//!   uses ([`register_clouds`], [`Mapped::from_prepared`]), so the registered points and
//!   mapped waypoints equal the CLI's output files (tested to 1e-6 mm in
//!   `host-sim/python/tests/test_register.py`).
//! * The interpreter is released (`Python::detach`) while a template is prepared, a
//!   registration runs or points are mapped.
//! * Errors: bad input raises `ValueError` carrying the core's or the reader's message;
//!   a registration the core refuses (the CLI's exit 2: a rib side not seen, an
//!   ambiguous pose, a waypoint the sweep does not reach, ...) raises `RegistrationError`,
//!   a `ValueError` whose `code` is the core error's wire code (`error_summary`); a file
//!   the operating system cannot read or write raises `OSError`.
//! * Waypoints to drive to go through `register(..., waypoints=...)`, which checks each
//!   one against what the sweep shows, as `ribreg register --waypoints` does;
//!   `Registration.transform` maps any points and checks none.

use numpy::ndarray::{Array1, Array2};
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArray2, PyArrayLike1, PyArrayLike2};
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use ribreg_core::error::Cloud as Which;
use ribreg_core::registration::local_rigid::TransformCache;
use ribreg_core::registration::pipeline::{
    Registration as CoreRegistration, Template as CoreTemplate,
};
use ribreg_core::wire::error_code;
use ribreg_core::{Error as CoreError, Vec3};
use ribreg_sim::io::prepared::TemplateFile;
use ribreg_sim::io::{self, Cloud, IoError};
use ribreg_sim::register::{
    build_template, check_edges, register_clouds, supported, to_core, to_file, Mapped, Method,
    Options, HOST_CACHE,
};
use ribreg_sim::sweep;
use std::path::PathBuf;
use std::time::Duration;

pyo3::create_exception!(
    ribreg._ribreg,
    RegistrationError,
    PyValueError,
    "The core refused the registration (`ribreg register` exits 2): a rib side not seen, \
     a sweep cut short, an ambiguous pose, a template the sweep does not support, a \
     waypoint the sweep does not reach. A `ValueError`; `code` is the core error's wire \
     code (`ribreg.error_summary(code)`), the message the CLI's."
);

/// A core error of a registration as `RegistrationError` with its wire code.
fn refused(py: Python<'_>, e: &CoreError) -> PyErr {
    let err = RegistrationError::new_err(e.to_string());
    match err.value(py).setattr("code", error_code(e)) {
        Ok(()) => err,
        Err(setting) => setting,
    }
}

/// Adds the registration API to the module.
pub fn add(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("RegistrationError", m.py().get_type::<RegistrationError>())?;
    m.add_class::<Template>()?;
    m.add_class::<Registration>()?;
    m.add_function(wrap_pyfunction!(register, m)?)?;
    m.add_function(wrap_pyfunction!(read_cloud, m)?)?;
    m.add_function(wrap_pyfunction!(read_waypoints, m)?)?;
    Ok(())
}

/// A reader's or writer's error as the Python exception a user expects.
fn io_err(e: IoError) -> PyErr {
    match e {
        IoError::Io { .. } => PyOSError::new_err(e.to_string()),
        IoError::Format { .. } => PyValueError::new_err(e.to_string()),
    }
}

fn value_err(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// An (N, 3) array-like as f64 rows; `what` names it in the error.
fn rows(a: &PyArrayLike2<'_, f64, AllowTypeChange>, what: &str) -> PyResult<Vec<[f64; 3]>> {
    let v = a.as_array();
    if v.ncols() != 3 {
        return Err(PyValueError::new_err(format!(
            "{what}: expected an (N, 3) array of points, got shape ({}, {})",
            v.nrows(),
            v.ncols()
        )));
    }
    Ok(v.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

/// Points (f64 rows) → an (N, 3) float64 array.
fn to_array<'py>(py: Python<'py>, points: &[[f64; 3]]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = points.iter().flatten().copied().collect();
    // Note(unwrap): the length is 3 N by construction.
    #[allow(clippy::unwrap_used)]
    let a = Array2::from_shape_vec((points.len(), 3), flat).unwrap();
    a.into_pyarray(py)
}

/// Labels (one per template point) → core labels 0..=5 (1 = sternum, 2..5 = rib).
fn core_labels(labels: impl Iterator<Item = i64>) -> PyResult<Vec<u8>> {
    labels
        .enumerate()
        .map(|(i, l)| {
            u8::try_from(l).ok().filter(|l| *l <= 5).ok_or_else(|| {
                PyValueError::new_err(format!(
                    "labels[{i}] = {l} is not a rib number 2..5 (1 = sternum, 0 = unlabelled)"
                ))
            })
        })
        .collect()
}

/// Template labels (array-like of integers, one per point) → core labels.
fn labels_of(
    labels: Option<PyArrayLike1<'_, i64, AllowTypeChange>>,
    points: usize,
) -> PyResult<Option<Vec<u8>>> {
    let Some(labels) = labels else {
        return Ok(None);
    };
    let v = labels.as_array();
    if v.len() != points {
        return Err(PyValueError::new_err(format!(
            "labels: {} labels for {points} template points",
            v.len()
        )));
    }
    core_labels(v.iter().copied()).map(Some)
}

fn method_of(name: &str) -> PyResult<Method> {
    match name {
        "improved" => Ok(Method::Improved),
        "paper" => Ok(Method::Paper),
        other => Err(PyValueError::new_err(format!(
            "method: {other:?} is not one of \"improved\", \"paper\""
        ))),
    }
}

/// A template prepared once (skeleton graph, rib order, the 30 skeleton points) and
/// reused for every registration; saved and loaded in the format of
/// `ribreg template --prepared`.
///
/// `Template(points, labels)` prepares one from a labelled cloud (labels: 1 = sternum,
/// 2..5 = rib, one per point), as `ribreg register` does for the improved method.
#[pyclass(frozen, module = "ribreg")]
pub struct Template {
    cloud: Cloud,
    core: CoreTemplate,
    /// The cloud as the core has it (f32).
    points: Vec<Vec3>,
}

impl Template {
    fn prepare(py: Python<'_>, cloud: Cloud) -> PyResult<Self> {
        let points = to_core(&cloud.points, Which::Template).map_err(value_err)?;
        let labels = labels_of_cloud(&cloud)?.ok_or_else(|| {
            PyValueError::new_err(
                "a template needs labels (1 = sternum, 2..5 = rib, one per point)",
            )
        })?;
        let core = py
            .detach(|| build_template(&points, Some(&labels), Method::Improved, &mut |_| {}))
            .map_err(value_err)?;
        Ok(Template {
            cloud,
            core,
            points,
        })
    }
}

fn labels_of_cloud(cloud: &Cloud) -> PyResult<Option<Vec<u8>>> {
    cloud
        .labels
        .as_ref()
        .map(|l| core_labels(l.iter().map(|&l| i64::from(l))))
        .transpose()
}

#[pymethods]
impl Template {
    #[new]
    fn new(
        py: Python<'_>,
        points: PyArrayLike2<'_, f64, AllowTypeChange>,
        labels: PyArrayLike1<'_, i64, AllowTypeChange>,
    ) -> PyResult<Self> {
        let points = rows(&points, "points")?;
        let labels =
            labels_of(Some(labels), points.len())?.map(|l| l.into_iter().map(i32::from).collect());
        Self::prepare(py, Cloud { points, labels })
    }

    /// Loads a template file: a prepared template (`ribreg template --prepared`) as it
    /// is, or a labelled cloud (any format `read_cloud` reads), prepared now.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let ply = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
        let file = if ply {
            io::prepared::read_template_file(&path).map_err(io_err)?
        } else {
            TemplateFile::Cloud(io::read_cloud(&path).map_err(io_err)?)
        };
        match file {
            TemplateFile::Cloud(cloud) => Self::prepare(py, cloud)
                .map_err(|e| PyValueError::new_err(format!("{}: {e}", path.display()))),
            TemplateFile::Prepared(p) => {
                let core = ribreg_sim::template::prepared::from_file(&p)
                    .map_err(|e| PyValueError::new_err(format!("{}: {e}", path.display())))?;
                let points = to_core(&p.cloud.points, Which::Template).map_err(value_err)?;
                Ok(Template {
                    cloud: p.cloud,
                    core,
                    points,
                })
            }
        }
    }

    /// Saves the prepared template (binary PLY, the format of `ribreg template
    /// --prepared`), to be loaded with `Template.load` or given to `ribreg register
    /// --template`.
    fn save(&self, path: PathBuf) -> PyResult<()> {
        let file = ribreg_sim::template::prepared::to_file(&self.cloud, &self.core);
        io::prepared::write_prepared(&path, &file).map_err(io_err)
    }

    /// The template cloud, (N, 3) float64, mm.
    #[getter]
    fn points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_array(py, &self.cloud.points)
    }

    /// Its labels, (N,) int32: 1 = sternum, 2..5 = rib.
    #[getter]
    fn labels<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i32>> {
        Array1::from(self.cloud.labels.clone().unwrap_or_default()).into_pyarray(py)
    }

    /// The 30 skeleton points of the template (6 per rib side, ribs 2..5 and the sternum
    /// edge), (30, 3) float64, mm.
    #[getter]
    fn skeleton<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_array(py, &to_file(&self.core.skeleton.points))
    }

    fn __len__(&self) -> usize {
        self.cloud.points.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "Template({} points, {} SOM-1 nodes)",
            self.cloud.points.len(),
            self.core.graph.som1.len()
        )
    }
}

/// The result of `ribreg.register`: the non-rigid mapping template → target and its report.
#[pyclass(frozen, module = "ribreg")]
pub struct Registration {
    registration: Box<CoreRegistration>,
    registered: Vec<[f64; 3]>,
    /// The mapped waypoints and whether each is supported, when waypoints were given.
    waypoints: Option<(Vec<[f64; 3]>, Vec<bool>)>,
    report: String,
}

#[pymethods]
impl Registration {
    /// Maps points (any (N, 3) array-like, template frame, mm) into the target, and
    /// checks none of them against what the sweep shows: for waypoints the probe is to
    /// be driven to, give them to `register(..., waypoints=...)`. Returns (N, 3) float64.
    fn transform<'py>(
        &self,
        py: Python<'py>,
        points: PyArrayLike2<'py, f64, AllowTypeChange>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let pts = rows(&points, "points")?;
        let mut pts = to_core(&pts, Which::Query).map_err(value_err)?;
        let reg = &self.registration;
        py.detach(|| {
            let mut cache = Box::new(TransformCache::<HOST_CACHE>::new());
            reg.map_in_place(&mut pts, &mut cache)
        })
        .map_err(value_err)?;
        Ok(to_array(py, &to_file(&pts)))
    }

    /// The template's points mapped into the target, (N, 3) float64, template order
    /// (what `ribreg register --out` writes).
    #[getter]
    fn registered<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_array(py, &self.registered)
    }

    /// The waypoints given to `register`, mapped into the target, (M, 3) float64; `None`
    /// when none were given (what `ribreg register --out-waypoints` writes).
    #[getter]
    fn waypoints<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        self.waypoints.as_ref().map(|(w, _)| to_array(py, w))
    }

    /// Per mapped waypoint, whether the sweep supports it, (M,) bool: all `True` unless
    /// `register` was called with `partial=True`, which marks (`False`) the waypoints
    /// the sweep does not reach instead of refusing — never drive to those. `None`
    /// without waypoints (the CSV's `supported` column of `ribreg register --partial`).
    #[getter]
    fn supported<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<bool>>> {
        self.waypoints
            .as_ref()
            .map(|(_, s)| Array1::from(s.clone()).into_pyarray(py))
    }

    /// The report `ribreg register --report` writes, as a dict: the paired skeleton
    /// points (`skeleton`), the rigid part (`endpoint_match`), ED / HD (`metrics`), the
    /// mapping's counters (`mapping`) and timings in ms (`timings_ms`).
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let json = py.import("json")?;
        json.call_method1("loads", (self.report.as_str(),))?
            .cast_into::<PyDict>()
            .map_err(PyErr::from)
    }

    /// The rigid part of the registration, template → target, as a 4 × 4 homogeneous
    /// matrix (float64, mm): the pose the endpoint match found, before the local
    /// non-rigid corrections.
    #[getter]
    fn rigid<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let r = self.registration.pose.inverse();
        let mut m = Array2::<f64>::eye(4);
        for i in 0..3 {
            for j in 0..3 {
                m[(i, j)] = f64::from(r.rotation[(i, j)]);
            }
            m[(i, 3)] = f64::from(r.translation[i]);
        }
        m.into_pyarray(py)
    }

    fn __repr__(&self) -> String {
        format!(
            "Registration({} template points mapped)",
            self.registered.len()
        )
    }
}

/// Registers a template onto a target cloud (any pose: no initial alignment needed).
///
/// `template` is an (N, 3) array-like with `labels` (one per point: 1 = sternum,
/// 2..5 = rib; required by the improved method), or a `Template`. `prepared` is a
/// `Template` already prepared from this same `template` cloud, to skip preparing it
/// again. `method` is `"improved"` (default) or `"paper"` (the paper's method as
/// published; no prepared template).
///
/// `waypoints` ((M, 3), template frame, mm) are mapped and each is checked against
/// what the sweep shows, as `ribreg register --waypoints` does: a waypoint the sweep
/// does not reach raises `RegistrationError` (code 24), or with `partial=True` is marked
/// in `Registration.supported`. `target_up` is the patient's anterior in the target's
/// frame, roughly (three numbers, `ribreg register --target-up`). `imaged` is the file of
/// the sweep's lines the target was compounded from (`ribreg compound --imaged`): a rib
/// end the sweep did not image at least 3 mm past raises `RegistrationError` (code 27),
/// or with `partial=True` marks that side's waypoints, as `ribreg register --imaged`
/// does. `partial`, `target_up` and `imaged` need the improved method.
#[pyfunction]
#[pyo3(signature = (
    template, target, labels=None, *, waypoints=None, partial=false, target_up=None,
    method="improved", prepared=None, imaged=None
))]
#[allow(clippy::too_many_arguments)]
fn register(
    py: Python<'_>,
    template: &Bound<'_, PyAny>,
    target: PyArrayLike2<'_, f64, AllowTypeChange>,
    labels: Option<PyArrayLike1<'_, i64, AllowTypeChange>>,
    waypoints: Option<PyArrayLike2<'_, f64, AllowTypeChange>>,
    partial: bool,
    target_up: Option<PyArrayLike1<'_, f64, AllowTypeChange>>,
    method: &str,
    prepared: Option<PyRef<'_, Template>>,
    imaged: Option<PathBuf>,
) -> PyResult<Registration> {
    let method = method_of(method)?;
    let imaged = match &imaged {
        Some(path) => {
            let rows = io::read_table_csv(path, sweep::IMAGED_COLUMNS).map_err(io_err)?;
            let area = sweep::lines_from_rows(&rows)
                .map_err(|e| PyValueError::new_err(format!("{}: {e}", path.display())))?;
            Some(Box::new(area))
        }
        None => None,
    };
    let target = rows(&target, "target")?;
    let target = to_core(&target, Which::Target).map_err(value_err)?;
    let waypoints = match &waypoints {
        Some(w) => Some(to_core(&rows(w, "waypoints")?, Which::Query).map_err(value_err)?),
        None => None,
    };
    let target_up = target_up.map(|v| direction(&v)).transpose()?;
    if method == Method::Paper && (partial || target_up.is_some() || imaged.is_some()) {
        return Err(PyValueError::new_err(
            "partial, target_up and imaged need the improved method (the paper's has no rib \
             extents and no pose hypotheses)",
        ));
    }
    let how = Options {
        method,
        target_up,
        partial,
        ..method.into()
    };
    let given: Option<PyRef<'_, Template>> = template.extract().ok();
    if given.is_some() && (labels.is_some() || prepared.is_some()) {
        return Err(PyValueError::new_err(
            "template is a Template: labels and prepared come from it",
        ));
    }
    let prepared = given.or(prepared);
    if let Some(p) = &prepared {
        if method != Method::Improved {
            return Err(PyValueError::new_err(
                "a prepared template is the improved method's; give method=\"paper\" the template cloud",
            ));
        }
        if !template.is_instance_of::<Template>() {
            let cloud = rows(&template.extract()?, "template")?;
            if cloud != p.cloud.points {
                return Err(PyValueError::new_err(
                    "prepared was prepared from another cloud than template",
                ));
            }
        }
    }
    let outcome = match prepared {
        Some(p) => {
            let (core, points) = (p.core.clone(), &p.points);
            py.detach(|| {
                Mapped::from_prepared(
                    core,
                    points,
                    true,
                    &target,
                    waypoints.as_deref(),
                    how,
                    Duration::ZERO,
                    &mut |_| {},
                )
                .map(|mapped| mapped.measure(&mut |_| {}))
            })
        }
        None => {
            let cloud = rows(&template.extract()?, "template")?;
            let points = to_core(&cloud, Which::Template).map_err(value_err)?;
            let labels = labels_of(labels, points.len())?;
            if method == Method::Improved && labels.is_none() {
                return Err(PyValueError::new_err(
                    "the improved method needs template labels (1 = sternum, 2..5 = rib); \
                     use method=\"paper\" for an unlabelled template",
                ));
            }
            py.detach(|| {
                register_clouds(
                    &points,
                    labels.as_deref(),
                    &target,
                    waypoints.as_deref(),
                    how,
                    &mut |_| {},
                )
            })
        }
    }
    .map_err(|e| refused(py, &e))?;
    // The rib ends against where the sweep imaged: refused, or with a partial plan that
    // side marked (and refused when nothing is kept).
    let cut = match &imaged {
        Some(area) => {
            check_edges(&outcome.registration, &outcome.reach, area, partial)
                .map_err(|e| refused(py, &e))?
                .1
        }
        None => [false; 2],
    };
    let mapped = outcome.waypoints.as_deref().map(|w| {
        // Only a partial plan marks waypoints: every other one was checked in full.
        let marks = if partial {
            supported(&outcome.reach, cut)
        } else {
            vec![true; w.len()]
        };
        (to_file(w), marks)
    });
    Ok(Registration {
        registered: to_file(&outcome.registered),
        waypoints: mapped,
        report: outcome.report.to_string(),
        registration: outcome.registration,
    })
}

/// `ribreg register --target-up`'s direction: three finite numbers, not all zero.
fn direction(v: &PyArrayLike1<'_, f64, AllowTypeChange>) -> PyResult<Vec3> {
    let v: Vec<f32> = v.as_array().iter().map(|&c| c as f32).collect();
    ribreg_sim::register::direction(&v).ok_or_else(|| {
        PyValueError::new_err(format!(
            "target_up: expected a direction of three finite numbers, not all zero, got {v:?}"
        ))
    })
}

/// Reads a point cloud in any format `ribreg` reads (PLY, PCD, XYZ, CSV; by the
/// extension): returns `(points, labels)`, (N, 3) float64 and (N,) int32 or `None`
/// when the file has no labels.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn read_cloud<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Option<Bound<'py, PyArray1<i32>>>)> {
    let cloud = io::read_cloud(&path).map_err(io_err)?;
    Ok((
        to_array(py, &cloud.points),
        cloud.labels.map(|l| Array1::from(l).into_pyarray(py)),
    ))
}

/// Reads waypoints in any format `ribreg register --waypoints` reads (CSV, Slicer
/// `.mrk.json`, `.fcsv`): returns `(points, labels)`, (N, 3) float64 in the patient
/// frame and a list of N labels (empty strings where the file has none).
#[pyfunction]
fn read_waypoints<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Vec<String>)> {
    let w = io::read_waypoints(&path).map_err(io_err)?;
    let n = w.points.len();
    let mut labels = w.labels;
    labels.resize(n, String::new());
    Ok((to_array(py, &w.points), labels))
}
