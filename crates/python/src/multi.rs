//! `MultiEnv`: a race of several cars (`agvrl.make_multi` wraps it in a PettingZoo
//! `ParallelEnv`).

use crate::{Bounds, bounds, config, env_err, floats, guard, info, lock};
use agvrl_envs::{MultiEnv as _, RaceEnv};
use numpy::{PyArray1, PyReadonlyArrayDyn};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::sync::Mutex;

/// Per agent (`None` for an agent already done): obs, reward, terminated, truncated, info;
/// then the race's results once it is over.
type MultiOut<'py> = (
    Bound<'py, PyList>,
    Bound<'py, PyList>,
    Bound<'py, PyList>,
    Bound<'py, PyList>,
    Bound<'py, PyList>,
    Option<Bound<'py, PyDict>>,
);

/// A multi-agent env (`agvrl envs` lists the ids under "multi-agent").
#[pyclass(module = "agvrl._core")]
pub struct MultiEnv {
    inner: Mutex<RaceEnv>,
    id: String,
    n: usize,
    obs_space: agvrl_envs::BoxSpace,
    act_space: agvrl_envs::BoxSpace,
    dt_s: f64,
}

#[pymethods]
impl MultiEnv {
    /// `MultiEnv(env_id, config)`: `config` as for `Env`, with `race` (cars, rewards, grid).
    #[new]
    #[pyo3(signature = (env_id, config=None))]
    fn new(env_id: &str, config: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        guard(|| {
            let cfg = config::env_config(config)?;
            let env = agvrl_envs::make_race(env_id, &cfg).map_err(env_err)?;
            Ok(Self {
                n: env.n_agents(),
                obs_space: env.observation_space(),
                act_space: env.action_space(),
                dt_s: env.dt_s(),
                inner: Mutex::new(env),
                id: env_id.to_string(),
            })
        })
    }

    /// The env id.
    #[getter]
    fn id(&self) -> &str {
        &self.id
    }

    /// Number of agents (cars).
    #[getter]
    fn n_agents(&self) -> usize {
        self.n
    }

    /// Control period, seconds.
    #[getter]
    fn dt(&self) -> f64 {
        self.dt_s
    }

    /// Each agent's observation bounds `(low, high)`.
    fn observation_bounds<'py>(&self, py: Python<'py>) -> Bounds<'py> {
        bounds(py, &self.obs_space)
    }

    /// Each agent's action bounds `(low, high)`.
    fn action_bounds<'py>(&self, py: Python<'py>) -> Bounds<'py> {
        bounds(py, &self.act_space)
    }

    /// Start a race: `seed` reseeds, `None` continues the stream. One observation per agent.
    #[pyo3(signature = (seed=None))]
    fn reset<'py>(&self, py: Python<'py>, seed: Option<u64>) -> PyResult<Bound<'py, PyList>> {
        guard(|| {
            let obs = py
                .detach(|| guard(|| Ok(lock(&self.inner)?.reset(seed))))?
                .map_err(env_err)?;
            PyList::new(py, obs.into_iter().map(|o| PyArray1::from_vec(py, o)))
        })
    }

    /// One action per agent (a list of float32 arrays; an agent already done may pass
    /// anything of the right shape). See `MultiOut`.
    fn step<'py>(&self, py: Python<'py>, actions: Vec<PyReadonlyArrayDyn<'py, f32>>) -> PyResult<MultiOut<'py>> {
        guard(|| {
            if actions.len() != self.n {
                return Err(PyValueError::new_err(format!(
                    "{} actions for {} agents",
                    actions.len(),
                    self.n
                )));
            }
            let a = actions.iter().map(floats).collect::<PyResult<Vec<_>>>()?;
            let st = py
                .detach(|| guard(|| Ok(lock(&self.inner)?.step(&a))))?
                .map_err(env_err)?;
            let (obs, rew, term, trunc, infos) = (
                PyList::empty(py),
                PyList::empty(py),
                PyList::empty(py),
                PyList::empty(py),
                PyList::empty(py),
            );
            for s in &st.agents {
                match s {
                    Some(s) => {
                        obs.append(PyArray1::from_slice(py, &s.obs))?;
                        rew.append(s.reward)?;
                        term.append(s.terminated)?;
                        trunc.append(s.truncated)?;
                        infos.append(info::single(py, &s.info)?)?;
                    }
                    None => {
                        for l in [&obs, &rew, &term, &trunc, &infos] {
                            l.append(py.None())?;
                        }
                    }
                }
            }
            let summary = st.summary.as_ref().map(|s| info::race_summary(py, s)).transpose()?;
            Ok((obs, rew, term, trunc, infos, summary))
        })
    }
}
