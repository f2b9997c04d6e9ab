//! Settings from Python: dicts become the TOML tables a run file holds and are parsed by the
//! same serde types, so unknown keys and bad values read as the CLI prints them.

use agvrl::config::RunConfig;
use agvrl_envs::EnvConfig;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use std::path::PathBuf;
use toml::{Table, Value};

/// A Python value as TOML; `where_` names it in errors. `None` means "absent" to the caller.
fn to_toml(v: &Bound<'_, PyAny>, where_: &str) -> PyResult<Option<Value>> {
    Ok(Some(if v.is_none() {
        return Ok(None);
    } else if v.is_instance_of::<PyBool>() {
        Value::Boolean(v.extract()?)
    } else if v.is_instance_of::<PyInt>() {
        Value::Integer(
            v.extract()
                .map_err(|_| PyValueError::new_err(format!("{where_}: integer out of range")))?,
        )
    } else if v.is_instance_of::<PyFloat>() {
        Value::Float(v.extract()?)
    } else if v.is_instance_of::<PyString>() {
        Value::String(v.extract()?)
    } else if let Ok(d) = v.cast::<PyDict>() {
        Value::Table(to_table(d, where_)?)
    } else if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let mut a = Vec::new();
        for (i, x) in v.try_iter()?.enumerate() {
            let x = x?;
            a.extend(to_toml(&x, &format!("{where_}[{i}]"))?);
        }
        Value::Array(a)
    } else if let Ok(b) = v.extract::<bool>() {
        // numpy.bool_ (pyo3 reads it as a bool)
        Value::Boolean(b)
    } else if let Ok(i) = v.extract::<i64>() {
        // numpy integers (`__index__`)
        Value::Integer(i)
    } else if let Ok(f) = v.extract::<f64>() {
        // numpy.float32 (`__float__`)
        Value::Float(f)
    } else {
        return Err(PyValueError::new_err(format!(
            "{where_}: a {} cannot be a setting (use numbers, strings, bools, lists and dicts)",
            v.get_type().name()?
        )));
    }))
}

fn to_table(d: &Bound<'_, PyDict>, where_: &str) -> PyResult<Table> {
    let mut t = Table::new();
    for (k, v) in d.iter() {
        let k: String = k
            .extract()
            .map_err(|_| PyValueError::new_err(format!("{where_}: setting names must be strings")))?;
        let w = format!("{where_}.{k}");
        if let Some(v) = to_toml(&v, &w)? {
            t.insert(k, v);
        }
    }
    Ok(t)
}

/// `over` on top of `base`, tables merged key by key.
fn merge(base: &mut Table, over: Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(Value::Table(b)), Value::Table(o)) => merge(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

fn value_err(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// Env settings from `agvrl.make(..., **config)`: the keys of `[env_config]`, on top of
/// `preset` (default, paper or sim2real) when given.
pub fn env_config(config: Option<&Bound<'_, PyDict>>) -> PyResult<EnvConfig> {
    let mut t = match config {
        Some(d) => to_table(d, "env_config")?,
        None => Table::new(),
    };
    let base = match t.remove("preset") {
        Some(Value::String(p)) => EnvConfig::preset(&p).map_err(value_err)?,
        Some(_) => return Err(PyValueError::new_err("env_config.preset must be a string")),
        None => EnvConfig::default(),
    };
    let mut full = Table::try_from(&base).map_err(value_err)?;
    merge(&mut full, t);
    let text = toml::to_string(&full).map_err(value_err)?;
    toml::from_str(&text)
        .map_err(|e: toml::de::Error| PyValueError::new_err(format!("env_config: {}", e.message().trim())))
}

/// A run config from a TOML path or a dict, with `overrides` (a dict of the same keys) on top,
/// validated as `agvrl train` validates it.
pub fn run_config(config: &Bound<'_, PyAny>, overrides: Option<&Bound<'_, PyDict>>) -> PyResult<RunConfig> {
    let (mut t, origin) = if let Ok(d) = config.cast::<PyDict>() {
        (to_table(d, "config")?, "config".to_string())
    } else {
        let path: PathBuf = config
            .extract()
            .map_err(|_| PyValueError::new_err("config must be a run TOML's path or a dict of its keys"))?;
        let text = std::fs::read_to_string(&path)
            .map_err(|e| PyValueError::new_err(format!("cannot read {}: {e}", path.display())))?;
        let t: Table = toml::from_str(&text).map_err(|e: toml::de::Error| {
            PyValueError::new_err(format!("{}: {}", path.display(), e.message().trim()))
        })?;
        (t, path.display().to_string())
    };
    if let Some(o) = overrides {
        merge(&mut t, to_table(o, "overrides")?);
    }
    let text = toml::to_string(&t).map_err(value_err)?;
    RunConfig::from_toml(&text, &origin).map_err(|e| PyValueError::new_err(agvrl_run::error_line(&e)))
}

fn to_py<'py>(py: Python<'py>, v: &Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Integer(i) => i.into_pyobject(py)?.into_any(),
        Value::Float(f) => f.into_pyobject(py)?.into_any(),
        Value::Boolean(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Value::Datetime(d) => d.to_string().into_pyobject(py)?.into_any(),
        Value::Array(a) => PyList::new(py, a.iter().map(|x| to_py(py, x)).collect::<PyResult<Vec<_>>>()?)?.into_any(),
        Value::Table(t) => {
            let d = PyDict::new(py);
            for (k, x) in t {
                d.set_item(k, to_py(py, x)?)?;
            }
            d.into_any()
        }
    })
}

/// Env settings as a dict `agvrl.make` takes back.
pub fn to_dict<'py>(py: Python<'py>, cfg: &EnvConfig) -> PyResult<Bound<'py, PyDict>> {
    let t = Table::try_from(cfg).map_err(value_err)?;
    Ok(to_py(py, &Value::Table(t))?.cast_into::<PyDict>()?)
}
