//! `ribreg.sim`'s Rust half: what `ribreg hil` simulates around the protocol — the
//! phantom and its sweep, the upload prepared from them, the robot that follows
//! setpoints, and the firmware under QEMU — from `ribreg_sim::hil`, unchanged.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyList;
use ribreg_core::math::geom::Rigid;
use ribreg_core::wire::{FromController, ToController};
use ribreg_sim::hil::{self, emulator, robot, RunOptions};
use ribreg_sim::phantom::{PhantomConfig, Variant};
use std::io::Write;
use std::net::Shutdown;
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use super::convert::{from_py_msg, to_py_msg};
use super::{link_error, LinkError, LinkSession};

/// Adds the simulation's classes and functions to the module.
pub fn add(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("STANDOFF_MM", robot::STANDOFF_MM)?;
    m.add("ROBOT_LAG_S", robot::ROBOT_LAG_S)?;
    m.add("TOLERANCE_MM", hil::TOLERANCE_MM)?;
    m.add_class::<SimScenario>()?;
    m.add_class::<SimRobot>()?;
    m.add_class::<SimEmulator>()?;
    m.add_function(wrap_pyfunction!(emulator_available, m)?)?;
    Ok(())
}

fn as_list<'py, T: serde::Serialize>(py: Python<'py>, msgs: &[T]) -> PyResult<Bound<'py, PyList>> {
    let items = msgs
        .iter()
        .map(|m| to_py_msg(py, m))
        .collect::<PyResult<Vec<_>>>()?;
    PyList::new(py, items)
}

/// A phantom, its simulated sweep and the upload `ribreg hil` prepares from them
/// (`ribreg_sim::hil::prepare`).
#[pyclass(module = "ribreg._ribreg", frozen)]
pub struct SimScenario {
    upload: Vec<ToController>,
    sweep: Vec<ToController>,
    truth: Vec<[f64; 3]>,
    standing: Option<([f64; 3], [f64; 4])>,
    sweep_end_s: f64,
    ee_t_tcp: Rigid,
    lag_s: f64,
    nodes: usize,
}

#[pymethods]
impl SimScenario {
    /// The phantom of `seed` (`variant` "aligned" or "misaligned", as `ribreg hil
    /// --seed --variant`), swept as `ribreg hil` sweeps it (`quick`: as `--quick`).
    #[new]
    #[pyo3(signature = (seed = 0, quick = true, variant = "aligned"))]
    fn new(py: Python<'_>, seed: u64, quick: bool, variant: &str) -> PyResult<Self> {
        let variant = match variant {
            "aligned" => Variant::Aligned,
            "misaligned" => Variant::Misaligned,
            v => {
                return Err(PyValueError::new_err(format!(
                    "variant {v:?}: expected \"aligned\" or \"misaligned\""
                )))
            }
        };
        let phantom = PhantomConfig {
            seed,
            variant,
            ..PhantomConfig::default()
        };
        let options = if quick {
            RunOptions::quick()
        } else {
            RunOptions::default()
        };
        let p = py
            .detach(|| hil::prepare(&phantom, &options.sweep))
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(SimScenario {
            sweep: robot::sweep_messages(&p.logs),
            truth: p.logs.pair.true_waypoints.clone(),
            standing: p.logs.poses.last().map(|r| (r.position, r.quaternion)),
            sweep_end_s: p.logs.poses.last().map_or(0.0, |r| r.t),
            ee_t_tcp: p.logs.calibration.ee_t_tcp,
            lag_s: p.lag_s,
            nodes: p.nodes,
            upload: p.upload,
        })
    }

    /// The video lag the temporal calibration measured, ms.
    #[getter]
    fn lag_ms(&self) -> f64 {
        self.lag_s * 1e3
    }

    /// Template nodes in the upload.
    #[getter]
    fn nodes(&self) -> usize {
        self.nodes
    }

    /// Planned waypoints in the upload.
    #[getter]
    fn waypoints(&self) -> usize {
        self.truth.len()
    }

    /// The upload after the handshake, in order (serde form): the configuration, the
    /// template's node chunks, its shape, the waypoint chunks.
    fn upload<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        as_list(py, &self.upload)
    }

    /// The sweep's poses (100 Hz) and frames (30 fps) in arrival order (serde form).
    fn sweep_messages<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        as_list(py, &self.sweep)
    }

    /// Time of the sweep's last pose, s (0 without poses).
    #[getter]
    fn sweep_end_s(&self) -> f64 {
        self.sweep_end_s
    }

    /// The phantom's true waypoints (robot base frame), mm.
    #[getter]
    fn true_waypoints(&self) -> Vec<[f64; 3]> {
        self.truth.clone()
    }

    /// The robot standing where the sweep ended.
    fn robot(&self) -> PyResult<SimRobot> {
        robot::Robot::standing(self.standing, self.ee_t_tcp)
            .map(|r| SimRobot {
                robot: Mutex::new(r),
            })
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }
}

/// The simulated robot and probe (`ribreg_sim::hil::robot::Robot`): stands still after
/// the sweep; while executing, its TCP follows each setpoint with a first-order lag.
#[pyclass(module = "ribreg._ribreg")]
pub struct SimRobot {
    robot: Mutex<robot::Robot>,
}

impl SimRobot {
    fn lock(&self) -> PyResult<MutexGuard<'_, robot::Robot>> {
        self.robot
            .lock()
            .map_err(|_| PyValueError::new_err("the robot failed in another thread"))
    }
}

#[pymethods]
impl SimRobot {
    /// Its flange pose report stamped `t_us` (a `Pose` message, serde form).
    fn pose<'py>(&self, py: Python<'py>, t_us: u64) -> PyResult<Bound<'py, PyAny>> {
        to_py_msg(py, &self.lock()?.pose(t_us))
    }

    /// Starts executing: the TCP is where the standing flange holds it.
    fn start_executing(&self) -> PyResult<()> {
        self.lock()?.start_executing();
        Ok(())
    }

    /// Moves the TCP 10 ms toward a `Setpoint` message (serde form).
    fn follow(&self, setpoint: &Bound<'_, PyAny>) -> PyResult<()> {
        let FromController::Setpoint(sp) = from_py_msg(setpoint)? else {
            return Err(PyValueError::new_err("follow takes a Setpoint"));
        };
        self.lock()?
            .follow(&sp)
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// Updates the flange from the TCP (before a pose report while executing).
    fn update_flange(&self) -> PyResult<()> {
        self.lock()?.update_flange();
        Ok(())
    }

    /// Where the probe aims now: the TCP plus `STANDOFF_MM` along its beam, mm.
    fn aim_point(&self) -> PyResult<[f64; 3]> {
        Ok(robot::aim_point(&self.lock()?.tcp()))
    }
}

/// Whether `qemu-system-arm` runs here.
#[pyfunction]
fn emulator_available() -> bool {
    emulator::qemu_available(std::path::Path::new(emulator::QEMU))
}

/// The firmware under QEMU as `ribreg hil` runs it (`-icount shift=0,sleep=on`), its
/// UART on a loopback TCP port. QEMU is killed when this is closed or collected.
#[pyclass(module = "ribreg._ribreg")]
pub struct SimEmulator {
    emu: Mutex<Option<emulator::Emulator>>,
    port: u16,
}

impl SimEmulator {
    /// Runs `f` on the emulator without the GIL, locked inside (as `LinkSession`).
    fn with<T: Send>(
        &self,
        py: Python<'_>,
        f: impl FnOnce(&mut emulator::Emulator) -> PyResult<T> + Send,
    ) -> PyResult<T> {
        py.detach(|| {
            let mut g = self
                .emu
                .lock()
                .map_err(|_| LinkError::new_err("the emulator failed in another thread"))?;
            match g.as_mut() {
                Some(e) => f(e),
                None => Err(LinkError::new_err("the emulator was closed")),
            }
        })
    }
}

#[pymethods]
impl SimEmulator {
    /// Builds the firmware if needed (or takes `RIBREG_FIRMWARE_ELF`), starts QEMU and
    /// connects to its UART.
    #[staticmethod]
    fn start(py: Python<'_>) -> PyResult<Self> {
        let emu = py
            .detach(|| -> Result<emulator::Emulator, emulator::QemuError> {
                let elf = emulator::firmware_elf()?;
                emulator::Emulator::start(&elf, &hil::emulator_options(None))
            })
            .map_err(|e| LinkError::new_err(e.to_string()))?;
        Ok(SimEmulator {
            port: emu.port(),
            emu: Mutex::new(Some(emu)),
        })
    }

    /// The UART's loopback port: `127.0.0.1:{port}` is the controller's `HOST:PORT`
    /// once `release_uart` has let go of it.
    #[getter]
    fn port(&self) -> u16 {
        self.port
    }

    /// A session over the UART connection this emulator holds.
    fn session(&self, py: Python<'_>) -> PyResult<LinkSession> {
        self.with(py, |e| {
            let stream = e
                .serial()
                .try_clone()
                .map_err(|err| LinkError::new_err(format!("emulator serial port: {err}")))?;
            Ok(LinkSession::over(Box::new(hil::Stream::new(stream))))
        })
    }

    /// Lets go of the UART connection so that another client (`Session.connect`,
    /// `robot_pc.py --port`) can connect to `127.0.0.1:{port}`: QEMU's server takes
    /// the next connection.
    fn release_uart(&self, py: Python<'_>) -> PyResult<()> {
        self.with(py, |e| {
            e.serial()
                .shutdown(Shutdown::Both)
                .map_err(|err| LinkError::new_err(format!("emulator serial port: {err}")))
        })
    }

    /// Ends the firmware over the held UART connection (`QUIT`) and waits up to
    /// `timeout` s for QEMU to exit; returns its exit code (0: clean).
    #[pyo3(signature = (timeout = 30.0))]
    fn quit(&self, py: Python<'_>, timeout: f64) -> PyResult<Option<i32>> {
        self.with(py, |e| {
            e.serial()
                .write_all(b"QUIT\0")
                .map_err(|err| LinkError::new_err(format!("emulator serial port: {err}")))?;
            e.wait(Duration::from_secs_f64(timeout.max(0.0)))
                .map(|s| s.code())
                .map_err(|err| link_error(err.into()))
        })
    }

    /// QEMU's stderr so far.
    fn stderr_output(&self, py: Python<'_>) -> PyResult<String> {
        self.with(py, |e| Ok(e.stderr_output()))
    }

    /// Kills QEMU (if still running).
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        py.detach(|| {
            let mut g = self
                .emu
                .lock()
                .map_err(|_| LinkError::new_err("the emulator failed in another thread"))?;
            if let Some(mut e) = g.take() {
                e.kill();
            }
            Ok(())
        })
    }
}
