//! SAC's replay buffer (raw observations; normalised when sampled, as SB3 does with
//! `VecNormalize`).

use crate::normalize::ObsNormalizer;
use crate::rng::Rng;

/// A ring of transitions; storage grows with use up to `capacity`.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplayBuffer {
    pub(crate) capacity: usize,
    pub(crate) obs_dim: usize,
    pub(crate) act_dim: usize,
    pub(crate) obs: Vec<f32>,
    pub(crate) next_obs: Vec<f32>,
    /// Actions scaled to [-1, 1].
    pub(crate) actions: Vec<f32>,
    pub(crate) rewards: Vec<f32>,
    /// 1 where the episode terminated (not on truncation: those bootstrap).
    pub(crate) dones: Vec<f32>,
    /// Next write slot.
    pub(crate) pos: usize,
}

/// A sampled minibatch, flat row-major.
pub struct Batch {
    /// `batch * obs_dim` observations (normalised if a normaliser was given).
    pub obs: Vec<f32>,
    /// `batch * act_dim` actions in [-1, 1].
    pub actions: Vec<f32>,
    /// `batch` rewards.
    pub rewards: Vec<f32>,
    /// `batch * obs_dim` next observations.
    pub next_obs: Vec<f32>,
    /// `batch` termination flags (1.0 / 0.0).
    pub dones: Vec<f32>,
}

impl ReplayBuffer {
    /// An empty buffer.
    pub fn new(capacity: usize, obs_dim: usize, act_dim: usize) -> Self {
        Self {
            capacity,
            obs_dim,
            act_dim,
            obs: vec![],
            next_obs: vec![],
            actions: vec![],
            rewards: vec![],
            dones: vec![],
            pos: 0,
        }
    }

    /// Transitions stored.
    pub fn len(&self) -> usize {
        self.rewards.len()
    }

    /// Whether nothing is stored.
    pub fn is_empty(&self) -> bool {
        self.rewards.is_empty()
    }

    /// Store one transition, overwriting the oldest once full.
    pub fn push(&mut self, obs: &[f32], action: &[f32], reward: f32, next_obs: &[f32], terminated: bool) {
        let done = if terminated { 1.0 } else { 0.0 };
        if self.len() < self.capacity {
            self.obs.extend_from_slice(obs);
            self.next_obs.extend_from_slice(next_obs);
            self.actions.extend_from_slice(action);
            self.rewards.push(reward);
            self.dones.push(done);
        } else {
            let (o, a, i) = (self.obs_dim, self.act_dim, self.pos);
            self.obs[i * o..(i + 1) * o].copy_from_slice(obs);
            self.next_obs[i * o..(i + 1) * o].copy_from_slice(next_obs);
            self.actions[i * a..(i + 1) * a].copy_from_slice(action);
            self.rewards[i] = reward;
            self.dones[i] = done;
        }
        self.pos = (self.pos + 1) % self.capacity;
    }

    /// `batch` transitions drawn uniformly with replacement (the buffer must not be empty).
    pub fn sample(&self, batch: usize, rng: &mut Rng, normalizer: Option<&ObsNormalizer>) -> Batch {
        let (o, a, n) = (self.obs_dim, self.act_dim, self.len());
        let mut b = Batch {
            obs: Vec::with_capacity(batch * o),
            actions: Vec::with_capacity(batch * a),
            rewards: Vec::with_capacity(batch),
            next_obs: Vec::with_capacity(batch * o),
            dones: Vec::with_capacity(batch),
        };
        for _ in 0..batch {
            let i = rng.below(n);
            b.obs.extend_from_slice(&self.obs[i * o..(i + 1) * o]);
            b.next_obs.extend_from_slice(&self.next_obs[i * o..(i + 1) * o]);
            b.actions.extend_from_slice(&self.actions[i * a..(i + 1) * a]);
            b.rewards.push(self.rewards[i]);
            b.dones.push(self.dones[i]);
        }
        if let Some(norm) = normalizer {
            norm.normalize_rows(&mut b.obs, o);
            norm.normalize_rows(&mut b.next_obs, o);
        }
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_overwrites_oldest() {
        let mut b = ReplayBuffer::new(3, 1, 1);
        for i in 0..5 {
            b.push(&[i as f32], &[0.0], i as f32, &[i as f32 + 1.0], false);
        }
        assert_eq!(b.len(), 3);
        let mut r = b.rewards.clone();
        r.sort_by(f32::total_cmp);
        assert_eq!(r, vec![2.0, 3.0, 4.0]);
        let s = b.sample(50, &mut Rng::new(1), None);
        assert!(s.obs.iter().zip(&s.next_obs).all(|(o, n)| n - o == 1.0));
    }
}
