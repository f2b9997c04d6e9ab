#!/usr/bin/env python3
"""One PPO minibatch through Stable-Baselines3's policy, against agvrl's: load the weights and
the minibatch agvrl dumped (`cargo run --release -p agvrl-rl --features parity --example parity --
--dump-grads FILE [sde|gaussian] [seed]`), compute SB3's loss (PPO.train's lines: clipped surrogate +
vf_coef * MSE) with autograd at the weights after agvrl's first update (ratios away from 1, some
clipped), and print the relative difference of every gradient tensor.

    python tools/parity/sb3_gradient_check.py FILE [sde|gaussian] [--no-shuffle]

Then SB3's GAE on agvrl's rewards and values, and SB3's own PPO.train() on agvrl's first
rollout from the weights the rollout was collected with; with --no-shuffle (both sides) the minibatches come in the same
order, so the update's clip fraction and std must agree to float rounding.
"""
import json
import sys

import numpy as np
import torch as th
import torch.nn.functional as F
from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env


def main():
    path = sys.argv[1]
    sde = "gaussian" not in sys.argv[2:]
    d = json.load(open(path))
    shapes, params, grads = d["shapes"], d["params"], d["grads"]
    m = PPO("MlpPolicy", make_vec_env("Pendulum-v1", n_envs=4, seed=0), device="cpu", use_sde=sde,
            n_steps=1024, gamma=0.9, learning_rate=1e-3, sde_sample_freq=4)
    pol = m.policy
    # agvrl: [members, in, out] row-major; torch Linear: weight [out, in].
    mapping = [  # (torch parameter, agvrl tensor index, member)
        (pol.mlp_extractor.policy_net[0].weight, 0, 0), (pol.mlp_extractor.policy_net[0].bias, 1, 0),
        (pol.mlp_extractor.value_net[0].weight, 0, 1), (pol.mlp_extractor.value_net[0].bias, 1, 1),
        (pol.mlp_extractor.policy_net[2].weight, 2, 0), (pol.mlp_extractor.policy_net[2].bias, 3, 0),
        (pol.mlp_extractor.value_net[2].weight, 2, 1), (pol.mlp_extractor.value_net[2].bias, 3, 1),
        (pol.action_net.weight, 4, 0), (pol.action_net.bias, 5, 0),
        (pol.value_net.weight, 6, 0), (pol.value_net.bias, 7, 0),
    ]

    def load(weights):
        """agvrl's tensors (layout [members, in, out]) into SB3's policy."""
        W = lambda i: np.array(weights[i], dtype=np.float32).reshape(shapes[i])
        with th.no_grad():
            for t, i, k in mapping:
                w = W(i)[k]  # [in, out]
                t.copy_(th.from_numpy(w.T.copy()).reshape(t.shape) if t.dim() == 2 else th.from_numpy(w.reshape(-1)))
            pol.log_std.copy_(th.from_numpy(W(8)[0].reshape(pol.log_std.shape)))

    load(params)
    pol.set_training_mode(True)
    n = len(d["old_log_prob"])
    obs = th.tensor(d["obs"], dtype=th.float32).reshape(n, -1)
    act = th.tensor(d["actions"], dtype=th.float32).reshape(n, -1)
    old_lp = th.tensor(d["old_log_prob"], dtype=th.float32)
    adv = th.tensor(d["advantages"], dtype=th.float32)
    ret = th.tensor(d["returns"], dtype=th.float32)
    pol.optimizer.zero_grad()
    values, log_prob, entropy = pol.evaluate_actions(obs, act)
    values = values.flatten()
    ratio = th.exp(log_prob - old_lp)
    policy_loss = -th.min(adv * ratio, adv * th.clamp(ratio, 0.8, 1.2)).mean()
    value_loss = F.mse_loss(ret, values)
    loss = policy_loss + 0.5 * value_loss
    loss.backward()
    with th.no_grad():
        log_ratio = log_prob - old_lp
        kl = th.mean((th.exp(log_ratio) - 1) - log_ratio).item()
    print(f"pg_loss sb3={policy_loss.item():.6g} agvrl={d['pg_loss']:.6g}")
    print(f"vf_loss sb3={value_loss.item():.6g} agvrl={d['vf_loss']:.6g}")
    with th.no_grad():
        cf = th.mean((th.abs(ratio - 1) > 0.2).float()).item()
    print(f"approx_kl sb3={kl:.4g} agvrl={d['approx_kl']:.4g}; clip_fraction sb3={cf:.4g} agvrl={d['clip_fraction']:.4g}")
    G = lambda i: np.array(grads[i], dtype=np.float64).reshape(shapes[i])
    worst = 0.0
    for (t, i, k), name in zip(mapping, ["pi0.w", "pi0.b", "vf0.w", "vf0.b", "pi2.w", "pi2.b", "vf2.w", "vf2.b",
                                         "action.w", "action.b", "value.w", "value.b"]):
        g_ours = G(i)[k]
        g_sb3 = t.grad.detach().numpy().astype(np.float64)
        g_sb3 = g_sb3.T if g_sb3.ndim == 2 else g_sb3
        g_ours = g_ours.reshape(g_sb3.shape)
        rel = np.linalg.norm(g_ours - g_sb3) / max(np.linalg.norm(g_sb3), 1e-30)
        worst = max(worst, rel)
        print(f"grad {name:9s} |sb3|={np.linalg.norm(g_sb3):.4g} |agvrl|={np.linalg.norm(g_ours):.4g} rel_diff={rel:.2e}")
    g_ls = pol.log_std.grad.detach().numpy().astype(np.float64).reshape(-1)
    o_ls = G(8).reshape(-1)
    rel = np.linalg.norm(o_ls - g_ls) / max(np.linalg.norm(g_ls), 1e-30)
    worst = max(worst, rel)
    print(f"grad log_std   |sb3|={np.linalg.norm(g_ls):.4g} |agvrl|={np.linalg.norm(o_ls):.4g} rel_diff={rel:.2e}")
    print(f"worst_rel_diff={worst:.2e}")
    if "--write-golden" in sys.argv:
        # SB3's gradients in agvrl's layout, beside the inputs: crates/rl/tests/ checks agvrl's.
        out = sys.argv[sys.argv.index("--write-golden") + 1]
        sb3_grads = [np.zeros(int(np.prod(sh)), dtype=np.float32).reshape(sh) for sh in shapes]
        for t, i, k in mapping:
            g = t.grad.detach().numpy()
            sb3_grads[i][k] = (g.T if g.ndim == 2 else g.reshape(sb3_grads[i][k].shape))
        sb3_grads[8][0] = pol.log_std.grad.detach().numpy().reshape(sb3_grads[8][0].shape)
        # "clip_fraction" is agvrl's at dump time; "sb3_clip_fraction" is SB3's, what the test checks.
        golden = {k: d[k] for k in ["shapes", "params", "obs", "actions", "old_log_prob", "advantages", "returns",
                                    "clip_fraction"]}
        golden.update(use_sde=sde, sb3_pg_loss=policy_loss.item(), sb3_vf_loss=value_loss.item(), sb3_clip_fraction=cf,
                      sb3_grads=[g.reshape(-1).tolist() for g in sb3_grads])
        json.dump(golden, open(out, "w"))
        print(f"wrote {out}")

    # SB3's log-probabilities of agvrl's rollout actions at the weights the rollout was collected
    # with, against the ones agvrl stored at collection time (the ratios' denominators).
    load(d["params_before"])
    with th.no_grad():
        r_obs = th.tensor(d["rollout_obs"], dtype=th.float32).reshape(len(d["rollout_log_prob"]), -1)
        r_act = th.tensor(d["rollout_actions"], dtype=th.float32).reshape(len(d["rollout_log_prob"]), -1)
        _, lp_sb3, _ = pol.evaluate_actions(r_obs, r_act)
        lp_ours = th.tensor(d["rollout_log_prob"], dtype=th.float32)
        dlp = (lp_sb3 - lp_ours).abs()
        print(f"rollout_log_prob max_abs_diff={dlp.max().item():.3g} mean_abs_diff={dlp.mean().item():.3g} "
              f"(log-probs from {lp_ours.min().item():.3g} to {lp_ours.max().item():.3g}; "
              f"std {th.exp(pol.log_std).mean().item():.4f})")

    # SB3's GAE (RolloutBuffer.compute_returns_and_advantage) on agvrl's rewards and values.
    rb = m.rollout_buffer
    T, E = rb.buffer_size, rb.n_envs
    rew, val, starts, last_v, last_d = (np.array(x, dtype=np.float32) for x in d["gae_inputs"])
    rb.reset()
    rb.rewards[:] = rew.reshape(T, E)
    rb.values[:] = val.reshape(T, E)
    rb.episode_starts[:] = starts.reshape(T, E)
    rb.compute_returns_and_advantage(th.tensor(last_v), last_d)
    adv_ours = np.array(d["rollout_advantages"], dtype=np.float32).reshape(T, E)
    ret_ours = np.array(d["rollout_returns"], dtype=np.float32).reshape(T, E)
    print(f"gae max_abs_diff advantages={np.abs(rb.advantages - adv_ours).max():.3g} "
          f"returns={np.abs(rb.returns - ret_ours).max():.3g} (|adv| max {np.abs(adv_ours).max():.3g})")

    # SB3's own PPO.train() on agvrl's whole first rollout, from the same weights.
    rb.reset()
    rb.observations[:] = np.array(d["rollout_obs"], dtype=np.float32).reshape(T, E, -1)
    rb.actions[:] = np.array(d["rollout_actions"], dtype=np.float32).reshape(T, E, -1)
    rb.log_probs[:] = np.array(d["rollout_log_prob"], dtype=np.float32).reshape(T, E)
    rb.advantages[:] = np.array(d["rollout_advantages"], dtype=np.float32).reshape(T, E)
    rb.returns[:] = np.array(d["rollout_returns"], dtype=np.float32).reshape(T, E)
    rb.values[:] = rb.returns - rb.advantages
    rb.full = True
    from stable_baselines3.common.logger import configure
    m.set_logger(configure(None, []))
    load(d["params_before"])
    start = {k: v.clone() for k, v in pol.state_dict().items()}
    for rep in range(1):
        pol.load_state_dict(start)
        pol.optimizer = pol.optimizer_class(pol.parameters(), lr=1e-3, **pol.optimizer_kwargs)
        th.manual_seed(rep)
        np.random.seed(rep)
        rb.generator_ready = False
        if "--no-shuffle" in sys.argv:
            # agvrl's rollout order (step-major) in SB3's flattened buffer (env-major).
            np.random.permutation = lambda n: np.array([(k % E) * T + k // E for k in range(n)])
        m.train()
        v = m.logger.name_to_value
        print(f"sb3_train_on_agvrl_rollout rep={rep} approx_kl={v['train/approx_kl']:.5f} "
              f"clip_fraction={v['train/clip_fraction']:.4f} std={v.get('train/std', float('nan')):.4f}")
    # (From a fresh Adam on both sides only for the first rollout; after --after, agvrl's Adam
    # carries its moments, so these two lines agree only roughly.)
    print(f"agvrl_update_on_same_rollout approx_kl={d['update_approx_kl']:.5f} "
          f"clip_fraction={d['update_clip_fraction']:.4f} std={d['update_std']:.4f}")


if __name__ == "__main__":
    main()
