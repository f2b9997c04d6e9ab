//! Checkpoints: the whole training state of a learner (weights, target nets, optimiser moments,
//! normaliser, RNG, counters, SAC's replay buffer) in the container of [`crate::file`].
//!
//! Envs cannot be snapshotted through the `Env` trait, so a resumed run starts fresh episodes
//! (env reset with a seed derived from the run seed and the step count); everything the
//! learner owns continues exactly.

use crate::adam::Adam;
use crate::error::{Result, RlError};
use crate::file;
use crate::nets::HostParams;
use crate::normalize::ObsNormalizer;
use crate::policy::{Algorithm, check_space};
use crate::progress::Episodes;
use crate::rng::Rng;
use agvrl_envs::BoxSpace;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Version of the checkpoint layout this build writes and reads.
pub const CHECKPOINT_FORMAT_VERSION: u32 = 2;
/// Versions this build reads: 1 has no image encoder (its configs lack `image`), 2 may have one.
const CHECKPOINT_READS: [u32; 2] = [1, 2];
const CHECKPOINT_MAGIC: &[u8; 8] = b"AGVRLCKP";

/// The part of a checkpoint header every learner writes: spaces, seed, counters, episode
/// statistics, RNG and normaliser. Flattened into each learner's header, so the JSON keeps one
/// flat object.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct Common {
    observation_space: BoxSpace,
    action_space: BoxSpace,
    pub(crate) seed: u64,
    pub(crate) num_timesteps: u64,
    pub(crate) n_updates: u64,
    episodes: u64,
    recent_returns: Vec<f64>,
    pub(crate) rng: Rng,
    pub(crate) normalizer: Option<ObsNormalizer>,
}

impl Common {
    /// The state of a learner on `spaces` (observation, action).
    pub(crate) fn new(
        spaces: (&BoxSpace, &BoxSpace),
        seed: u64,
        counters: (u64, u64),
        episodes: &Episodes,
        rng: &Rng,
        normalizer: &Option<ObsNormalizer>,
    ) -> Self {
        Self {
            observation_space: spaces.0.clone(),
            action_space: spaces.1.clone(),
            seed,
            num_timesteps: counters.0,
            n_updates: counters.1,
            episodes: episodes.count,
            recent_returns: episodes.recent.iter().copied().collect(),
            rng: rng.clone(),
            normalizer: normalizer.clone(),
        }
    }

    /// The episode statistics.
    pub(crate) fn episodes(&self) -> Episodes {
        Episodes {
            count: self.episodes,
            recent: self.recent_returns.iter().copied().collect(),
        }
    }
}

/// A learner's checkpoint header: [`Common`] plus its own parts.
pub(crate) trait Header: DeserializeOwned {
    /// The common part.
    fn common(&self) -> &Common;
}

/// Adam's scalars; its moments travel as arrays.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct AdamMeta {
    lr: f64,
    beta1: f64,
    beta2: f64,
    eps: f64,
    t: u64,
}

/// Collects arrays in order for writing.
#[derive(Default)]
pub(crate) struct ArrayWriter<'a> {
    pub(crate) arrays: Vec<&'a [f32]>,
}

impl<'a> ArrayWriter<'a> {
    pub(crate) fn params(&mut self, p: &'a HostParams) {
        self.arrays.extend(p.data.iter().map(Vec::as_slice));
    }

    pub(crate) fn adam(&mut self, a: &'a Adam) -> AdamMeta {
        let (m, v) = a.moments();
        self.arrays.extend(m.iter().map(Vec::as_slice));
        self.arrays.extend(v.iter().map(Vec::as_slice));
        AdamMeta {
            lr: a.lr,
            beta1: a.beta1,
            beta2: a.beta2,
            eps: a.eps,
            t: a.t,
        }
    }

    pub(crate) fn array(&mut self, a: &'a [f32]) {
        self.arrays.push(a);
    }
}

/// Takes arrays back in the order they were written, checking lengths.
pub(crate) struct ArrayReader<'p> {
    it: std::vec::IntoIter<Vec<f32>>,
    path: &'p Path,
}

impl ArrayReader<'_> {
    fn bad(&self, reason: &str) -> RlError {
        RlError::BadFile {
            path: self.path.to_path_buf(),
            reason: reason.to_string(),
        }
    }

    pub(crate) fn array(&mut self, len: Option<usize>) -> Result<Vec<f32>> {
        let a = self
            .it
            .next()
            .ok_or_else(|| self.bad("checkpoint has too few arrays"))?;
        if len.is_some_and(|l| l != a.len()) {
            return Err(self.bad("checkpoint array has the wrong length for its configuration"));
        }
        Ok(a)
    }

    pub(crate) fn params(&mut self, shapes: &[[usize; 3]]) -> Result<HostParams> {
        let mut p = HostParams {
            shapes: vec![],
            data: vec![],
        };
        for s in shapes {
            let d = self.array(Some(s.iter().product()))?;
            p.push(*s, d);
        }
        Ok(p)
    }

    pub(crate) fn adam(&mut self, meta: &AdamMeta, shapes: &[[usize; 3]]) -> Result<Adam> {
        let m = self.params(shapes)?.data;
        let v = self.params(shapes)?.data;
        Ok(Adam::from_parts(
            meta.lr, meta.beta1, meta.beta2, meta.eps, meta.t, m, v,
        ))
    }

    pub(crate) fn finish(mut self) -> Result<()> {
        match self.it.next() {
            Some(_) => Err(self.bad("checkpoint has more arrays than its configuration needs")),
            None => Ok(()),
        }
    }
}

/// Write a checkpoint: `header` as JSON plus `arrays`, atomically.
pub(crate) fn write<H: Serialize>(path: &Path, header: &H, arrays: &ArrayWriter<'_>) -> Result<()> {
    let bytes = file::encode(CHECKPOINT_MAGIC, CHECKPOINT_FORMAT_VERSION, header, &arrays.arrays)?;
    file::write_atomic(path, &bytes)
}

/// Read a checkpoint written by `algorithm` for an env with `spaces` (observation, action): its
/// header and a reader over its arrays.
pub(crate) fn read<'p, H: Header>(
    path: &'p Path,
    algorithm: Algorithm,
    spaces: (&BoxSpace, &BoxSpace),
) -> Result<(H, ArrayReader<'p>)> {
    let (h, arrays): (serde_json::Value, _) = file::read(path, CHECKPOINT_MAGIC, &CHECKPOINT_READS, "checkpoint")?;
    let found = h
        .get("algorithm")
        .and_then(|a| a.as_str())
        .unwrap_or("unknown")
        .to_string();
    if found != algorithm.to_string() {
        return Err(RlError::Mismatch {
            what: "algorithm",
            file: found,
            env: algorithm.to_string(),
        });
    }
    let h: H = serde_json::from_value(h).map_err(|e| RlError::BadFile {
        path: path.to_path_buf(),
        reason: format!("checkpoint header: {e}"),
    })?;
    check_space("observation space", &h.common().observation_space, spaces.0)?;
    check_space("action space", &h.common().action_space, spaces.1)?;
    Ok((
        h,
        ArrayReader {
            it: arrays.into_iter(),
            path,
        },
    ))
}
