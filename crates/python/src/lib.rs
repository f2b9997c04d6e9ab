//! `agvrl._core`: the native half of the `agvrl` Python package. One env, a batch of envs (the
//! Rust `VecEnv`), a policy and the trainer, with numpy arrays in and out; the Gymnasium and
//! Stable-Baselines3 adapters are Python (python/agvrl).
//!
//! Invariants: no panic crosses into Python (every entry point catches them and raises
//! `RuntimeError`); the GIL is released whenever Rust steps, acts or trains; settings are
//! parsed by the same serde types as a run TOML, so a bad key reads as it does in the CLI.

mod config;
mod f110;
mod info;
mod multi;

use agvrl::episode::{SimEnv, make_sim_env};
use agvrl_envs::{Autoreset, Env as _, EnvConfig, EnvError, VecEnv as RustVecEnv, make};
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::{PyKeyboardInterrupt, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

/// `(low, high)` of a space.
type Bounds<'py> = (Bound<'py, PyArray1<f32>>, Bound<'py, PyArray1<f32>>);
/// `(obs, reward, terminated, truncated, info)`.
type StepOut<'py> = (Bound<'py, PyArray1<f32>>, f64, bool, bool, Bound<'py, PyDict>);

/// Run `f`, turning a panic into `RuntimeError` (Python never sees a Rust panic).
fn guard<T>(f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|p| {
        let msg = p
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| p.downcast_ref::<&str>().copied())
            .unwrap_or("unknown cause");
        Err(PyRuntimeError::new_err(format!(
            "agvrl: internal error (Rust panic): {msg}"
        )))
    })
}

/// Bad input (settings, ids, actions) is `ValueError`; everything else `RuntimeError`.
fn env_err(e: EnvError) -> PyErr {
    match e.innermost() {
        EnvError::Config(_)
        | EnvError::UnknownId { .. }
        | EnvError::ActionShape { .. }
        | EnvError::ActionNotFinite { .. } => PyValueError::new_err(e.to_string()),
        _ => PyRuntimeError::new_err(e.to_string()),
    }
}

fn lock<T>(m: &Mutex<T>) -> PyResult<MutexGuard<'_, T>> {
    m.lock()
        .map_err(|_| PyRuntimeError::new_err("agvrl: this object failed earlier and can no longer be used"))
}

/// A flat f32 view of a numpy array (any shape, C order), copied.
fn floats(a: &PyReadonlyArrayDyn<'_, f32>) -> PyResult<Vec<f32>> {
    Ok(a.as_slice()
        .map_err(|_| PyValueError::new_err("expected a C-contiguous float32 array"))?
        .to_vec())
}

/// A single env and its running episode return and length (reported as `episode` when an
/// episode ends, as the vector env reports it).
struct Single {
    env: Inner,
    ret: f64,
    len: u64,
}

/// What a single env holds: vehicle envs keep their concrete type so `render` can look into the
/// simulator.
enum Inner {
    Sim(Box<SimEnv>),
    Other(Box<dyn agvrl_envs::Env>),
}

impl Inner {
    fn env(&mut self) -> &mut dyn agvrl_envs::Env {
        match self {
            Inner::Sim(e) => e.as_mut(),
            Inner::Other(e) => e.as_mut(),
        }
    }
}

fn build(env_id: &str, cfg: &EnvConfig) -> Result<Inner, EnvError> {
    match make_sim_env(env_id, cfg) {
        Ok(Some(e)) => Ok(Inner::Sim(Box::new(e))),
        Ok(None) => Ok(Inner::Other(make(env_id, cfg)?)),
        Err(e) => Err(match e.downcast::<EnvError>() {
            Ok(e) => e,
            Err(e) => EnvError::Config(agvrl_run::error_line(e.as_ref())),
        }),
    }
}

/// One agvrl env (`agvrl.make` wraps it in a `gymnasium.Env`).
#[pyclass(module = "agvrl._core")]
struct Env {
    inner: Mutex<Single>,
    id: String,
    cfg: EnvConfig,
    obs_space: agvrl_envs::BoxSpace,
    act_space: agvrl_envs::BoxSpace,
    dt_s: f64,
    has_camera: bool,
    renders: bool,
}

#[pymethods]
impl Env {
    /// `Env(env_id, config)`: `config` is a dict with the keys of `[env_config]` in a run TOML
    /// (nested tables as dicts), plus `preset` (`default`, `paper`, `sim2real`) to start from.
    #[new]
    #[pyo3(signature = (env_id, config=None))]
    fn new(env_id: &str, config: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        guard(|| {
            let cfg = config::env_config(config)?;
            let mut inner = build(env_id, &cfg).map_err(env_err)?;
            let renders = matches!(inner, Inner::Sim(_));
            let e = inner.env();
            Ok(Self {
                obs_space: e.observation_space(),
                act_space: e.action_space(),
                dt_s: e.dt_s(),
                inner: Mutex::new(Single {
                    env: inner,
                    ret: 0.0,
                    len: 0,
                }),
                id: env_id.to_string(),
                has_camera: cfg.sim.camera.is_some(),
                renders,
                cfg,
            })
        })
    }

    /// The env id.
    #[getter]
    fn id(&self) -> &str {
        &self.id
    }

    /// Control period, seconds.
    #[getter]
    fn dt(&self) -> f64 {
        self.dt_s
    }

    /// Whether `render` draws frames: the env drives a simulated vehicle.
    #[getter]
    fn renders(&self) -> bool {
        self.renders
    }

    /// Observation bounds `(low, high)`, float32 arrays.
    fn observation_bounds<'py>(&self, py: Python<'py>) -> Bounds<'py> {
        bounds(py, &self.obs_space)
    }

    /// Action bounds `(low, high)`, float32 arrays.
    fn action_bounds<'py>(&self, py: Python<'py>) -> Bounds<'py> {
        bounds(py, &self.act_space)
    }

    /// Start an episode: `seed` reseeds the env's random stream, `None` continues it. Returns
    /// `(obs, info)`.
    #[pyo3(signature = (seed=None))]
    fn reset<'py>(
        &self,
        py: Python<'py>,
        seed: Option<u64>,
    ) -> PyResult<(Bound<'py, PyArray1<f32>>, Bound<'py, PyDict>)> {
        guard(|| {
            let (obs, info) = py
                .detach(|| {
                    guard(|| {
                        let mut g = lock(&self.inner)?;
                        (g.ret, g.len) = (0.0, 0);
                        Ok(g.env.env().reset(seed))
                    })
                })?
                .map_err(env_err)?;
            Ok((PyArray1::from_vec(py, obs), info::single(py, &info)?))
        })
    }

    /// Apply one action (float32, the action space's shape). Returns `(obs, reward,
    /// terminated, truncated, info)`. A NaN or wrong-length action raises `ValueError`.
    fn step<'py>(&self, py: Python<'py>, action: PyReadonlyArrayDyn<'py, f32>) -> PyResult<StepOut<'py>> {
        guard(|| {
            let a = floats(&action)?;
            let st = py
                .detach(|| {
                    guard(|| {
                        let mut g = lock(&self.inner)?;
                        let mut st = g.env.env().step(&a);
                        if let Ok(st) = &mut st {
                            g.ret += st.reward;
                            g.len += 1;
                            if st.done() {
                                st.info.episode = Some(agvrl_envs::api::EpisodeSummary { ret: g.ret, len: g.len });
                            }
                        }
                        Ok(st)
                    })
                })?
                .map_err(env_err)?;
            let info = info::single(py, &st.info)?;
            Ok((
                PyArray1::from_vec(py, st.obs),
                st.reward,
                st.terminated,
                st.truncated,
                info,
            ))
        })
    }

    /// An RGB image `(height, width, 3)`, uint8: the vehicle camera's frame when the env has a
    /// camera, else the scene from above with the car and its LiDAR rays (`size` pixels along
    /// the map's longer side). `None` for envs without a vehicle.
    #[pyo3(signature = (size=480))]
    fn render<'py>(&self, py: Python<'py>, size: u32) -> PyResult<Option<Bound<'py, PyArray3<u8>>>> {
        guard(|| {
            let image = py.detach(|| {
                guard(|| {
                    let g = lock(&self.inner)?;
                    let Inner::Sim(env) = &g.env else {
                        return Ok(None);
                    };
                    let inner = env.inner();
                    let frame = inner.last_frame();
                    if self.has_camera
                        && let Some(img) = frame.and_then(|f| f.image.as_ref())
                        && !img.rgb.is_empty()
                    {
                        return Ok(Some((img.rgb.clone(), img.width, img.height)));
                    }
                    let sim = inner.vehicle().sim();
                    let scan = frame.and_then(|f| f.scan.as_ref());
                    agvrl::plots::top_view(sim, scan, size.clamp(32, 4096))
                        .map(Some)
                        .map_err(|e| PyRuntimeError::new_err(format!("render: {}", agvrl_run::error_line(e.as_ref()))))
                })
            })?;
            image
                .map(|(rgb, w, h)| {
                    numpy::ndarray::Array3::from_shape_vec((h as usize, w as usize, 3), rgb)
                        .map(|a| a.into_pyarray(py))
                        .map_err(|e| PyRuntimeError::new_err(format!("render: {e}")))
                })
                .transpose()
        })
    }
}

/// A classical racer (`agvrl.Racer` wraps it): pure pursuit or follow-the-gap, acting on an
/// env's last frame as a policy acts on its observation.
#[pyclass(module = "agvrl._core")]
struct Racer {
    driver: Mutex<Box<dyn agvrl_envs::drivers::Driver>>,
}

#[pymethods]
impl Racer {
    /// `Racer(kind, env, speed_scale=1.0, raceline=None)`: `kind` is `pure-pursuit` or
    /// `follow-the-gap`; `env` the racing env it drives (its car's limits); `raceline` a CSV
    /// path for pure pursuit (default: the track's centre line).
    #[new]
    #[pyo3(signature = (kind, env, speed_scale=1.0, raceline=None))]
    fn new(kind: &str, env: &Env, speed_scale: f64, raceline: Option<PathBuf>) -> PyResult<Self> {
        guard(|| {
            let kind = agvrl_envs::drivers::RacerKind::of(kind).map_err(env_err)?;
            if !(speed_scale.is_finite() && speed_scale > 0.0 && speed_scale <= 1.0) {
                return Err(PyValueError::new_err(format!(
                    "speed_scale must be in (0, 1], got {speed_scale}"
                )));
            }
            let raceline = raceline
                .map(|p| {
                    std::fs::read_to_string(&p).map_err(|e| PyValueError::new_err(format!("{}: {e}", p.display())))
                })
                .transpose()?;
            let driver =
                agvrl_envs::drivers::make_racer(kind, &env.cfg, speed_scale, raceline.as_deref()).map_err(env_err)?;
            Ok(Self {
                driver: Mutex::new(driver),
            })
        })
    }

    /// The action (float32, the env's action space) the racer takes on `env`'s last frame;
    /// right after a reset it starts its episode (pure pursuit finds its place on the path).
    fn act<'py>(&self, py: Python<'py>, env: &Env) -> PyResult<Bound<'py, PyArray1<f32>>> {
        guard(|| {
            let a = py.detach(|| {
                guard(|| {
                    let g = lock(&env.inner)?;
                    let Inner::Sim(sim_env) = &g.env else {
                        return Err(PyValueError::new_err("a racer drives a vehicle env"));
                    };
                    let inner = sim_env.inner();
                    let Some(frame) = inner.last_frame() else {
                        return Err(PyRuntimeError::new_err("reset the env before the racer acts"));
                    };
                    use agvrl_envs::Vehicle as _;
                    let map = inner.vehicle().map();
                    let mut d = lock(&self.driver)?;
                    if g.len == 0 {
                        d.reset(frame, map);
                    }
                    let c = d.control(frame, map);
                    let [a0, a1] = env.cfg.action_mapping.action(c, inner.vehicle().steering_limit_rad());
                    Ok(vec![a0 as f32, a1 as f32])
                })
            })?;
            Ok(PyArray1::from_vec(py, a))
        })
    }
}

fn bounds<'py>(py: Python<'py>, s: &agvrl_envs::BoxSpace) -> Bounds<'py> {
    (PyArray1::from_slice(py, &s.low), PyArray1::from_slice(py, &s.high))
}

fn autoreset(mode: &str) -> PyResult<Autoreset> {
    Ok(match mode {
        "next_step" => Autoreset::NextStep,
        "same_step" => Autoreset::SameStep,
        "disabled" => Autoreset::Disabled,
        other => {
            return Err(PyValueError::new_err(format!(
                "unknown autoreset_mode '{other}'; use next_step, same_step or disabled"
            )));
        }
    })
}

/// `num_envs` envs of one id stepped together by the Rust `VecEnv` (`agvrl.make_vec` wraps it
/// in a `gymnasium.vector.VectorEnv`). Sub-env `i` is seeded `seed + i`.
#[pyclass(module = "agvrl._core")]
struct VecEnv {
    inner: Mutex<RustVecEnv<Box<dyn agvrl_envs::Env>>>,
    id: String,
    kind: info::Kind,
    n: usize,
    obs_dim: usize,
    act_dim: usize,
}

#[pymethods]
impl VecEnv {
    /// `VecEnv(env_id, num_envs, threads=None, autoreset_mode="next_step", config=None)`;
    /// `threads` defaults to the cores available (at most `num_envs`).
    #[new]
    #[pyo3(signature = (env_id, num_envs, threads=None, autoreset_mode="next_step", config=None))]
    fn new(
        env_id: &str,
        num_envs: usize,
        threads: Option<usize>,
        autoreset_mode: &str,
        config: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        guard(|| {
            if num_envs == 0 {
                return Err(PyValueError::new_err("num_envs must be at least 1"));
            }
            if threads == Some(0) {
                return Err(PyValueError::new_err("threads must be at least 1"));
            }
            let mode = autoreset(autoreset_mode)?;
            let cfg = config::env_config(config)?;
            let envs = (0..num_envs)
                .map(|_| make(env_id, &cfg))
                .collect::<Result<Vec<_>, _>>()
                .map_err(env_err)?;
            let threads = threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
            let v = RustVecEnv::with_autoreset(envs, threads, mode).map_err(env_err)?;
            Ok(Self {
                n: num_envs,
                obs_dim: v.observation_space().dim(),
                act_dim: v.action_space().dim(),
                kind: info::Kind::of(env_id),
                inner: Mutex::new(v),
                id: env_id.to_string(),
            })
        })
    }

    /// The env id.
    #[getter]
    fn id(&self) -> &str {
        &self.id
    }

    /// Number of envs.
    #[getter]
    fn num_envs(&self) -> usize {
        self.n
    }

    /// Threads stepping the envs.
    #[getter]
    fn threads(&self) -> PyResult<usize> {
        Ok(lock(&self.inner)?.threads())
    }

    /// Control period, seconds.
    #[getter]
    fn dt(&self) -> PyResult<f64> {
        Ok(lock(&self.inner)?.dt_s())
    }

    /// Observation bounds of one env `(low, high)`.
    fn observation_bounds<'py>(&self, py: Python<'py>) -> PyResult<Bounds<'py>> {
        Ok(bounds(py, lock(&self.inner)?.observation_space()))
    }

    /// Action bounds of one env `(low, high)`.
    fn action_bounds<'py>(&self, py: Python<'py>) -> PyResult<Bounds<'py>> {
        Ok(bounds(py, lock(&self.inner)?.action_space()))
    }

    /// Reset env `i` with `seeds[i]` (`None`: continue its stream) where `mask` is true (every
    /// env without a mask). Returns `(obs (n, obs_dim), infos)`; rows of envs not reset keep
    /// their last observation.
    #[pyo3(signature = (seeds, mask=None))]
    fn reset<'py>(
        &self,
        py: Python<'py>,
        seeds: Vec<Option<u64>>,
        mask: Option<Vec<bool>>,
    ) -> PyResult<(Bound<'py, PyArray2<f32>>, Bound<'py, PyDict>)> {
        guard(|| {
            let (obs, infos) = py
                .detach(|| guard(|| Ok(lock(&self.inner)?.reset_envs(seeds, mask.clone()))))?
                .map_err(env_err)?;
            let obs = self.rows(py, obs)?;
            let infos = info::batch(py, self.kind, &infos, mask.as_deref())?;
            Ok((obs, infos))
        })
    }

    /// Step every env with its row of `actions` (float32, `(n, act_dim)`). Returns `(obs,
    /// rewards float64, terminated, truncated, infos)`, numpy arrays with one row per env;
    /// `infos` is Gymnasium's dict of arrays (with `_key` masks).
    fn step<'py>(
        &self,
        py: Python<'py>,
        actions: PyReadonlyArrayDyn<'py, f32>,
    ) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
        guard(|| {
            if actions.shape() != [self.n, self.act_dim]
                && !(actions.ndim() == 1 && actions.len() == self.n * self.act_dim)
            {
                return Err(PyValueError::new_err(format!(
                    "actions have shape {:?}; this vector env takes ({}, {})",
                    actions.shape(),
                    self.n,
                    self.act_dim
                )));
            }
            let a = floats(&actions)?;
            let st = py
                .detach(|| guard(|| Ok(lock(&self.inner)?.step(&a))))?
                .map_err(env_err)?;
            let infos = info::batch(py, self.kind, &st.infos, None)?;
            let obs = self.rows(py, st.obs)?;
            (
                obs,
                PyArray1::from_vec(py, st.rewards),
                PyArray1::from_vec(py, st.terminated),
                PyArray1::from_vec(py, st.truncated),
                infos,
            )
                .into_pyobject(py)
        })
    }
}

impl VecEnv {
    fn rows<'py>(&self, py: Python<'py>, flat: Vec<f32>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        Array2::from_shape_vec((self.n, self.obs_dim), flat)
            .map(|a| a.into_pyarray(py))
            .map_err(|e| PyRuntimeError::new_err(format!("observation rows: {e}")))
    }
}

/// A trained policy file (`policy.agvrl`), for inference.
#[pyclass(module = "agvrl._core")]
struct Policy {
    inner: Mutex<agvrl_rl::Policy>,
    path: PathBuf,
    obs_dim: usize,
    act_dim: usize,
}

#[pymethods]
impl Policy {
    /// Load a policy file; a truncated or corrupted file raises `ValueError`.
    #[new]
    fn new(path: PathBuf) -> PyResult<Self> {
        guard(|| {
            let p =
                agvrl_rl::Policy::load(&path).map_err(|e| PyValueError::new_err(format!("{}: {e}", path.display())))?;
            Ok(Self {
                obs_dim: p.observation_space().dim(),
                act_dim: p.action_space().dim(),
                inner: Mutex::new(p),
                path,
            })
        })
    }

    /// The file it was loaded from.
    #[getter]
    fn path(&self) -> PathBuf {
        self.path.clone()
    }

    /// `ppo` or `sac`.
    #[getter]
    fn algorithm(&self) -> PyResult<String> {
        Ok(lock(&self.inner)?.algorithm().to_string())
    }

    /// Observation bounds the policy was trained on `(low, high)`.
    fn observation_bounds<'py>(&self, py: Python<'py>) -> PyResult<Bounds<'py>> {
        Ok(bounds(py, lock(&self.inner)?.observation_space()))
    }

    /// Action bounds `(low, high)`.
    fn action_bounds<'py>(&self, py: Python<'py>) -> PyResult<Bounds<'py>> {
        Ok(bounds(py, lock(&self.inner)?.action_space()))
    }

    /// The env id and `[env_config]` the policy drives with (embedded in the file; for older
    /// files the `.toml` beside it, or the run directory's config.toml), as agvrl-drive builds
    /// them, or `None` when it carries none.
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Option<(String, Bound<'py, PyDict>)>> {
        guard(|| {
            let src = {
                let inner = lock(&self.inner)?;
                agvrl_run::PolicySettings::of_policy(&self.path, inner.data(), &[])
                    .map_err(|e| PyValueError::new_err(agvrl_run::error_line(&e)))?
            };
            match &src.run {
                None => Ok(None),
                Some(run) => Ok(Some((run.env.clone(), config::to_dict(py, &src.drive_env_config())?))),
            }
        })
    }

    /// Reseed the sampling of stochastic actions.
    fn seed(&self, seed: u64) -> PyResult<()> {
        lock(&self.inner)?.seed(seed);
        Ok(())
    }

    /// Actions for one observation `(obs_dim,)` or a batch `(n, obs_dim)` (float32), as an
    /// array of the same rank; `deterministic` takes the distribution's mode.
    #[pyo3(signature = (obs, deterministic=true))]
    fn act<'py>(
        &self,
        py: Python<'py>,
        obs: PyReadonlyArrayDyn<'py, f32>,
        deterministic: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        guard(|| {
            let shape = obs.shape().to_vec();
            let rows = match shape[..] {
                [d] if d == self.obs_dim => 1,
                [n, d] if d == self.obs_dim => n,
                _ => {
                    return Err(PyValueError::new_err(format!(
                        "observation shape {shape:?}; the policy takes ({0},) or (n, {0})",
                        self.obs_dim
                    )));
                }
            };
            let x = floats(&obs)?;
            let out = py.detach(|| {
                guard(|| {
                    let mut p = lock(&self.inner)?;
                    let mut out = Vec::with_capacity(rows * self.act_dim);
                    for o in x.chunks_exact(self.obs_dim.max(1)) {
                        let a = p
                            .act(o, deterministic)
                            .map_err(|e| PyValueError::new_err(e.to_string()))?;
                        out.extend(a);
                    }
                    Ok(out)
                })
            })?;
            Ok(if shape.len() == 1 {
                PyArray1::from_vec(py, out).into_any()
            } else {
                Array2::from_shape_vec((rows, self.act_dim), out)
                    .map_err(|e| PyRuntimeError::new_err(e.to_string()))?
                    .into_pyarray(py)
                    .into_any()
            })
        })
    }
}

/// Run the Rust trainer on a run config (a TOML path, or a dict with a run TOML's keys) into a
/// run directory (`out`, else runs/<date-time>-<env>-<algo> under the working directory),
/// exactly as `agvrl train --config` does, with the GIL released. Ctrl-C stops it after the
/// current update with a complete run directory, then raises `KeyboardInterrupt`. Returns
/// `(run_dir, eval.json's text)`.
#[pyfunction]
#[pyo3(signature = (config, out=None, overrides=None, device="flex"))]
fn train(
    py: Python<'_>,
    config: &Bound<'_, PyAny>,
    out: Option<PathBuf>,
    overrides: Option<&Bound<'_, PyDict>>,
    device: &str,
) -> PyResult<(PathBuf, String)> {
    guard(|| {
        // Parsed and validated here, so a bad config is a ValueError before anything starts.
        let cfg = config::run_config(config, overrides)?;
        let stop = Arc::new(AtomicBool::new(false));
        let device: agvrl_rl::DeviceChoice = device
            .parse()
            .and_then(|d: agvrl_rl::DeviceChoice| d.check_built().map(|()| d))
            .map_err(|e: agvrl_rl::RlError| PyValueError::new_err(e.to_string()))?;
        let flag = stop.clone();
        let worker = std::thread::Builder::new()
            .name("agvrl-train".into())
            .spawn(move || {
                agvrl::train::train_run(cfg, out, device.into(), &flag, agvrl::train::ProgressMode::Bar)
                    .map_err(|e| agvrl_run::error_line(e.as_ref()))
            })
            .map_err(|e| PyRuntimeError::new_err(format!("starting the trainer: {e}")))?;
        // The trainer runs without the GIL; this thread wakes to let Python see Ctrl-C.
        let mut interrupted = None;
        while !worker.is_finished() {
            py.detach(|| std::thread::sleep(std::time::Duration::from_millis(50)));
            if interrupted.is_none()
                && let Err(e) = py.check_signals()
            {
                stop.store(true, Ordering::SeqCst);
                interrupted = Some(e);
            }
        }
        let (dir, report) = worker
            .join()
            .map_err(|_| PyRuntimeError::new_err("agvrl: internal error (the trainer panicked)"))?
            .map_err(PyRuntimeError::new_err)?;
        if let Some(e) = interrupted {
            if e.is_instance_of::<PyKeyboardInterrupt>(py) {
                eprintln!("agvrl: interrupted; the run directory {} is complete", dir.display());
            }
            return Err(e);
        }
        Ok((dir, report.to_json()))
    })
}

/// Steps per second of the Rust `VecEnv` alone (uniform random actions drawn in Rust), the
/// reference the Python bench compares itself to. `num_envs = 0` times one env without the
/// vector (the single-env reference).
#[pyfunction]
#[pyo3(signature = (env_id, num_envs, steps, threads=None, seed=0))]
fn bench_rust(
    py: Python<'_>,
    env_id: &str,
    num_envs: usize,
    steps: u64,
    threads: Option<usize>,
    seed: u64,
) -> PyResult<f64> {
    use rand::{RngExt, SeedableRng};
    guard(|| {
        let cfg = EnvConfig::default();
        py.detach(|| {
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            if num_envs == 0 {
                let mut env = make(env_id, &cfg).map_err(env_err)?;
                let d = env.action_space().dim();
                env.reset(Some(seed)).map_err(env_err)?;
                let t0 = std::time::Instant::now();
                for _ in 0..steps {
                    let a: Vec<f32> = (0..d).map(|_| rng.random_range(-1.0..=1.0)).collect();
                    if env.step(&a).map_err(env_err)?.done() {
                        env.reset(None).map_err(env_err)?;
                    }
                }
                return Ok(steps as f64 / t0.elapsed().as_secs_f64());
            }
            let envs = (0..num_envs)
                .map(|_| make(env_id, &cfg))
                .collect::<Result<Vec<_>, _>>()
                .map_err(env_err)?;
            let threads = threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
            let mut v = RustVecEnv::with_autoreset(envs, threads, Autoreset::NextStep).map_err(env_err)?;
            let d = v.action_space().dim();
            v.reset(Some(seed)).map_err(env_err)?;
            let t0 = std::time::Instant::now();
            for _ in 0..steps {
                let a: Vec<f32> = (0..d * num_envs).map(|_| rng.random_range(-1.0..=1.0)).collect();
                v.step(&a).map_err(env_err)?;
            }
            Ok((steps * num_envs as u64) as f64 / t0.elapsed().as_secs_f64())
        })
    })
}

/// A decoded bag message as Python objects.
struct ToPy<'py>(Python<'py>);

impl<'py> agvrl_deploy::record::Decoded for ToPy<'py> {
    type Out = Bound<'py, PyAny>;
    fn decoded<M: serde::Serialize>(self, m: &M) -> Result<Bound<'py, PyAny>, String> {
        pythonize::pythonize(self.0, m).map_err(|e| e.to_string())
    }
}

/// Every intact message of bag `path` as `(topic, type, log_ns, message)`, the message decoded
/// to dicts, lists, floats and bytes (the raw CDR bytes for a type without a decoder here),
/// and the damage found (`None` for an intact bag). A message that does not decode raises
/// `ValueError` naming it.
#[pyfunction]
fn bag_messages<'py>(py: Python<'py>, path: PathBuf) -> PyResult<(Bound<'py, PyList>, Option<String>)> {
    guard(|| {
        let (msgs, damage) = py
            .detach(|| agvrl_deploy::bag::read_messages(&path))
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        let out = PyList::empty(py);
        for m in &msgs {
            let value = match agvrl_deploy::record::decode_into(m, ToPy(py)) {
                Ok(v) => v,
                Err(e) if e.starts_with("no decoder") => pyo3::types::PyBytes::new(py, &m.data).into_any(),
                Err(e) => {
                    return Err(PyValueError::new_err(format!(
                        "{}: a {} message on {} logged at {} ns: {e}",
                        path.display(),
                        m.ty,
                        m.topic,
                        m.log_ns
                    )));
                }
            };
            out.append((m.topic.as_str(), m.ty.as_str(), m.log_ns, value))?;
        }
        Ok((out, damage))
    })
}

/// Replay bag `path` through the policy file `policy` (settings embedded in it, `overrides`
/// as `agvrl train --set`), as `agvrl-drive --replay` does; `config` is the car's TOML of a
/// car log. Returns a dict of numpy arrays, one row per recorded tick: the replayed
/// observation, action (NaN rows where the watchdog stopped the car), throttle and steering,
/// beside the recorded ones, plus the watchdog events and the bag's damage.
#[pyfunction]
#[pyo3(signature = (path, policy, config=None, overrides=Vec::new(), seed=0))]
fn replay_bag<'py>(
    py: Python<'py>,
    path: PathBuf,
    policy: PathBuf,
    config: Option<PathBuf>,
    overrides: Vec<String>,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    guard(|| {
        let value_err = |e: String| PyValueError::new_err(e);
        let rows = py.detach(|| -> Result<_, String> {
            let mut src = agvrl_run::PolicySettings::resolve(None, Some(&policy), &overrides)
                .map_err(|e| agvrl_run::error_line(&e))?;
            let loaded = src.load_policy().map_err(|e| agvrl_run::error_line(&e))?;
            let env = src.env_id(None).map_err(|e| agvrl_run::error_line(&e))?;
            let cfg = config
                .as_deref()
                .map(agvrl_deploy::hardware::Ros2Config::load)
                .transpose()
                .map_err(|e| e.to_string())?;
            let mut r =
                agvrl_deploy::replay::Replayer::open(&path, cfg, &env, &src.eval_env_config(), loaded, 30.0, seed)
                    .map_err(|e| format!("{}: {}", path.display(), agvrl_run::error_line(&e)))?;
            let mut rows = Vec::new();
            while let Some((rec, t)) = r.step().map_err(|e| agvrl_run::error_line(&e))? {
                rows.push((rec, t));
            }
            Ok((rows, r.vehicle().damage.clone(), r.vehicle().bad_messages()))
        });
        let (rows, damage, bad) = rows.map_err(value_err)?;
        let n = rows.len();
        let width = |f: &dyn Fn(&(agvrl_deploy::hardware::msg::Tick, agvrl_deploy::Tick)) -> usize| {
            rows.iter().map(f).max().unwrap_or(0)
        };
        let (n_obs, n_act) = (
            width(&|(r, t)| t.inference.as_ref().map_or(r.observation.len(), |(o, _)| o.len())),
            width(&|(r, t)| t.inference.as_ref().map_or(r.action.len(), |(_, a)| a.len())),
        );
        let table = |w: usize, row: &dyn Fn(usize) -> Option<Vec<f32>>| {
            let mut a = Array2::<f32>::from_elem((n, w), f32::NAN);
            for k in 0..n {
                if let Some(v) = row(k).filter(|v| v.len() == w) {
                    a.row_mut(k).assign(&numpy::ndarray::ArrayView1::from(&v[..]));
                }
            }
            a.into_pyarray(py)
        };
        let d = PyDict::new(py);
        let col = |f: &dyn Fn(&agvrl_deploy::hardware::msg::Tick, &agvrl_deploy::Tick) -> f64| {
            rows.iter().map(|(r, t)| f(r, t)).collect::<Vec<f64>>().into_pyarray(py)
        };
        d.set_item(
            "tick",
            rows.iter().map(|(r, _)| r.tick).collect::<Vec<u64>>().into_pyarray(py),
        )?;
        d.set_item("clock_s", col(&|r, _| r.clock_s))?;
        d.set_item("stamp_s", col(&|_, t| t.stamp_s))?;
        d.set_item(
            "observation",
            table(n_obs, &|k| rows[k].1.inference.as_ref().map(|(o, _)| o.clone())),
        )?;
        d.set_item(
            "action",
            table(n_act, &|k| rows[k].1.inference.as_ref().map(|(_, a)| a.clone())),
        )?;
        d.set_item("throttle", col(&|_, t| t.control.throttle))?;
        d.set_item("steering_rad", col(&|_, t| t.control.steering_rad))?;
        let events: Vec<String> = rows
            .iter()
            .map(|(_, t)| t.event.as_ref().map_or(String::new(), |e| format!("{e:?}")))
            .collect();
        d.set_item("event", events)?;
        // A tick the watchdog stopped recorded no observation and no action.
        let recorded = |v: &Vec<f32>| (!v.is_empty()).then(|| v.clone());
        d.set_item(
            "recorded_observation",
            table(n_obs, &|k| recorded(&rows[k].0.observation)),
        )?;
        d.set_item("recorded_action", table(n_act, &|k| recorded(&rows[k].0.action)))?;
        d.set_item("recorded_throttle", col(&|r, _| r.throttle))?;
        d.set_item("recorded_steering_rad", col(&|r, _| r.steering_rad))?;
        d.set_item(
            "recorded_event",
            rows.iter().map(|(r, _)| r.event.clone()).collect::<Vec<_>>(),
        )?;
        d.set_item("bad_messages", bad)?;
        d.set_item("damage", damage)?;
        Ok(d)
    })
}

/// Panic in Rust, with the GIL released, and raise what Python sees: the tests' check that no
/// panic crosses the boundary (every entry point goes through the same `guard`).
#[pyfunction]
fn _panic_for_test(py: Python<'_>, message: &str) -> PyResult<()> {
    guard(|| py.detach(|| guard(|| -> PyResult<()> { panic!("{message}") })))
}

/// Run the `agvrl` command line on `argv` (the program name first) with the GIL released, as
/// the `agvrl` binary does; returns its exit status. The wheel's `agvrl` script.
#[pyfunction]
fn cli(py: Python<'_>, argv: Vec<String>) -> PyResult<i32> {
    guard(|| Ok(py.detach(|| catch_unwind(|| agvrl::cli::main_with(argv)).unwrap_or(101))))
}

/// The multi-agent env ids (`agvrl.make_multi`).
#[pyfunction]
fn multi_env_ids(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    PyList::new(py, agvrl_envs::MULTI_ENV_IDS)
}

/// The registered env ids, as `agvrl envs` lists them.
#[pyfunction]
fn env_ids(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    PyList::new(py, agvrl_envs::ENV_IDS)
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Env>()?;
    m.add_class::<VecEnv>()?;
    m.add_class::<multi::MultiEnv>()?;
    m.add_class::<f110::F110Sim>()?;
    m.add_class::<Policy>()?;
    m.add_class::<Racer>()?;
    m.add_function(wrap_pyfunction!(train, m)?)?;
    m.add_function(wrap_pyfunction!(bench_rust, m)?)?;
    m.add_function(wrap_pyfunction!(env_ids, m)?)?;
    m.add_function(wrap_pyfunction!(multi_env_ids, m)?)?;
    m.add_function(wrap_pyfunction!(cli, m)?)?;
    m.add_function(wrap_pyfunction!(bag_messages, m)?)?;
    m.add_function(wrap_pyfunction!(replay_bag, m)?)?;
    m.add_function(wrap_pyfunction!(_panic_for_test, m)?)?;
    m.add("TERMINATION_CAUSES", info::CAUSES.to_vec())?;
    Ok(())
}
