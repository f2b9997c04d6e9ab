#!/usr/bin/env python3
"""The held-out tables of docs/search.md and the self-play results of docs/racing.md.

Every figure is read from the typed report `agvrl eval --json` (EvalReport,
crates/run/src/report.rs) or `agvrl race --json` (RaceReport, crates/run/src/race_report.rs)
writes into a temporary file, never from the `key=value` lines they print. A failed agvrl
run stops the table with its exit status (its stderr goes straight through). The wrappers
tools/search-table.sh, tools/search-safety-table.sh, tools/search-validate.sh and
tools/race-table.sh each run one subcommand:
  tools/tables.py search-table [POLICY] [EPISODES] [SEED] [FILTER]
  tools/tables.py search-safety-table [POLICY] [EPISODES] [SEED]
  tools/tables.py search-validate POLICY [POLICY ...]
  tools/tables.py race-table DUEL.agvrl LONE.agvrl [RACES] [SEED]
The agvrl binary is $AGVRL, else ${CARGO_TARGET_DIR:-target}/release/agvrl (the search tables
build it with `cargo build --release` when it is missing). Standard library only.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_POLICY = "assets/policies/search.agvrl"


def agvrl_bin(build):
    """The agvrl binary; with `build`, `cargo build --release` first when it is missing."""
    target = os.environ.get("CARGO_TARGET_DIR") or "target"
    path = os.environ.get("AGVRL") or f"{target}/release/agvrl"
    if build and not (os.path.isfile(path) and os.access(path, os.X_OK)):
        check(["cargo", "build", "--release", "-q"])
    return path


def fail(cmd, status):
    """Stop as `set -e` did: the command's own stderr is already shown."""
    print(f"tables.py: exit status {status}: {' '.join(cmd)}", file=sys.stderr)
    sys.exit(status)


def check(cmd, stdout=None):
    """Run `cmd` (stderr straight through); stop with its status if it fails."""
    try:
        done = subprocess.run(cmd, stdout=stdout, text=True)
    except OSError as e:
        print(f"tables.py: {cmd[0]}: {e.strerror}", file=sys.stderr)
        sys.exit(127)
    if done.returncode != 0:
        fail(cmd, done.returncode if done.returncode > 0 else 128 - done.returncode)
    return done.stdout


def report(cmd):
    """Run `agvrl eval`/`agvrl race` with `--json` into a temporary file and return that JSON.

    The printed `key=value` lines are dropped; the file is removed whatever happens."""
    fd, path = tempfile.mkstemp(prefix="agvrl-report-", suffix=".json")
    os.close(fd)
    try:
        check(cmd + ["--json", path], stdout=subprocess.DEVNULL)
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    finally:
        os.unlink(path)


def fmt(r, key, decimals=None):
    """A figure as `agvrl eval` prints it (its decimals); "" where the report has none."""
    v = r.get(key)
    if v is None:
        return ""
    if decimals is None or isinstance(v, int):
        return str(v)
    return f"{v:.{decimals}f}"


def printed(r, key, decimals):
    """A figure rounded as it prints: the tables' ratios and means are taken of the printed
    figures, as they were when the scripts read the printed lines (so their tables reproduce)."""
    return float(f"{r[key]:.{decimals}f}")


# --- the 16 held-out search rows ----------------------------------------------------------

def search_rows(policy, episodes, seed):
    """For every noise preset, maps and scene: (env, layouts, preset, `agvrl eval` arguments
    for `policy`, `episodes` and `seed`, 1,000 steps)."""
    for preset in ("none", "sim2real"):
        for layouts in ("builtin", "procedural"):
            for env in ("search-outdoor-20", "search-urban-20", "search-outdoor-50",
                        "search-urban-50"):
                args = ["eval", "--policy", policy, "--env", env, "--episodes", episodes,
                        "--seed", seed, "--layouts", layouts, "--max-steps", "1000"]
                if preset != "none":
                    args += ["--preset", preset]
                yield env, layouts, preset, args


def out(line):
    print(line, flush=True)


SEARCH_TABLE = """\
The held-out search table of docs/search.md: a policy and the uniform random policy on the same
100 held-out episodes (1,000 steps) of every search scene, on the built-in maps and on new
procedural layouts, without and with sim2real noise and randomisation.
  tools/search-table.sh [POLICY] [EPISODES] [SEED] [FILTER]
POLICY defaults to the shipped assets/policies/search.agvrl; SEED is the base of the
evaluation seeds (`agvrl eval --seed`); FILTER (on or off) overrides the policy's safety
filter setting for both the policy and the random policy (`agvrl eval --safety-filter`).
RANDOM_POLICY=off skips the random policy (its columns print "-"), for comparing trainings.
A policy with a reverse gear (action_mapping = "scaled_reverse") is also compared with the
random policy of the forward-only car (the same settings with `--set env_config.action_mapping=scaled`): a random policy that
reverses half the time covers less, and the ratio is taken against the better of the two.
"""


def search_table(policy, episodes, seed, filter_):
    os.chdir(ROOT)
    agvrl = agvrl_bin(build=True)
    settings = check([agvrl, "policy", policy], stdout=subprocess.PIPE)
    forward = any(line.startswith('action_mapping = "scaled_reverse"')
                  for line in settings.splitlines())
    random = "random (same car / forward only)" if forward else "random"
    out(f"| scene | maps | preset | policy: terminations / {episodes} | coverage | filter "
        f"interventions / episode | {random}: terminations | coverage | coverage ratio |")
    out("|---|---|---|---|---|---|---|---|---|")
    for env, layouts, preset, args in search_rows(policy, episodes, seed):
        if filter_:
            args += ["--safety-filter", filter_]
        p = report([agvrl] + args)
        rt = rc = ratio = "-"
        if os.environ.get("RANDOM_POLICY", "on") != "off":
            r = report([agvrl] + args + ["--random"])
            rt, rc, best = fmt(r, "collisions"), fmt(r, "coverage", 3), printed(r, "coverage", 3)
            if forward:
                f = report([agvrl] + args + ["--random", "--set",
                                              "env_config.action_mapping=scaled"])
                rt += f" / {fmt(f, 'collisions')}"
                rc += f" / {fmt(f, 'coverage', 3)}"
                best = max(best, printed(f, "coverage", 3))
            ratio = f"{printed(p, 'coverage', 3) / max(best, 1e-9):.1f}x"
        fi = fmt(p, "filter_interventions_per_episode", 1) or "off"
        out(f"| {env} | {layouts} | {preset} | {fmt(p, 'collisions')} | {fmt(p, 'coverage', 3)} "
            f"| {fi} | {rt} | {rc} | {ratio} |")


SEARCH_SAFETY_TABLE = """\
The held-out search table of the bare policy (docs/search.md): a policy with its safety filter
off (the bare network) and on, on the same 100 held-out episodes (1,000 steps) of every search scene, on
the built-in maps and on new procedural layouts, without and with sim2real noise and
randomisation; beside it the frontier explorer and the map-aware planner on the same car and
episodes, behind the filter they were tuned behind (the policy's training shield,
`--safety-filter train`: they drive at full throttle and leave braking to the filter).
  tools/search-safety-table.sh [POLICY] [EPISODES] [SEED]
POLICY defaults to the shipped assets/policies/search.agvrl; SEED is the base of the
evaluation seeds (`agvrl eval --seed`). PLANNERS=off skips the two planners (their columns
print "-"), for comparing trainings. CSV_DIR=DIR also writes every driver's coverage-over-time
CSV there (DIR/<env>-<maps>-<preset>-<driver>.csv, for `agvrl coverage-plot`).
"""


def search_safety_table(policy, episodes, seed):
    os.chdir(ROOT)
    agvrl = agvrl_bin(build=True)
    csv_dir = os.environ.get("CSV_DIR", "")

    def ratio(a, b):
        return f"{a / max(b, 1e-9):.2f}"

    out("| scene | maps | noise | bare: terminations | bare: coverage | bare / filtered coverage "
        "| filtered: terminations | filtered: coverage | corrections / episode (steered + "
        "braked) | back-outs / episode (reversing ticks) | r_m mean / 5th pct, m (bare; "
        "filtered) | steering change / control, rad (bare; filtered) | frontier: "
        "terminations, coverage | policy / frontier | map planner: coverage |")
    out("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for env, layouts, preset, args in search_rows(policy, episodes, seed):
        def run(name, *extra):
            cmd = [agvrl] + args + list(extra)
            if csv_dir:
                os.makedirs(csv_dir, exist_ok=True)
                cmd += ["--coverage-csv", f"{csv_dir}/{env}-{layouts}-{preset}-{name}.csv"]
            return report(cmd)

        b = run("bare", "--safety-filter", "off")
        f = run("policy", "--safety-filter", "on")
        fr = pf = pl = "-"
        if os.environ.get("PLANNERS", "on") != "off":
            q = run("frontier", "--safety-filter", "train", "--planner", "frontier")
            fr = f"{fmt(q, 'collisions')}, {fmt(q, 'coverage', 3)}"
            pf = ratio(printed(f, "coverage", 3), printed(q, "coverage", 3))
            m = run("planner", "--safety-filter", "train", "--planner", "map")
            pl = fmt(m, "coverage", 3)
        out(f"| {env} | {layouts} | {preset} | {fmt(b, 'collisions')} | {fmt(b, 'coverage', 3)} "
            f"| {ratio(printed(b, 'coverage', 3), printed(f, 'coverage', 3))} "
            f"| {fmt(f, 'collisions')} | {fmt(f, 'coverage', 3)} "
            f"| {fmt(f, 'filter_corrections_per_episode', 1)} "
            f"| {fmt(f, 'filter_backouts_per_episode', 2)} "
            f"({fmt(f, 'filter_backout_ticks_per_episode', 1)}) "
            f"| {fmt(b, 'clearance_mean_m', 3)} / {fmt(b, 'clearance_p5_m', 3)}; "
            f"{fmt(f, 'clearance_mean_m', 3)} / {fmt(f, 'clearance_p5_m', 3)} "
            f"| {fmt(b, 'steering_change_mean_rad', 4)}; {fmt(f, 'steering_change_mean_rad', 4)} "
            f"| {fr} | {pf} | {pl} |")


SEARCH_VALIDATE = """\
The validation score that picks which training of a search config ships (and the safety
filter's settings): terminations over 50 held-out episodes per search scene, on the built-in
maps and on new procedural layouts, without and with sim2real noise, with evaluation seeds from
1,000,000 (docs/search.md's table uses seed base 0, so the choice never sees the table's
episodes), with the filter on (validation_terminations) and off (validation_bare_terminations,
the same 800 episodes). The rule, for several policies: those within 2 filtered terminations
of the fewest; of them, those within 10 bare terminations of the fewest (the bare policy's
bounds are the primary target; 10 of 800 is under one episode per 100-episode row); of them,
the highest mean filtered coverage (the coverage targets are the ones a fresh training misses
next). It prints `picked=POLICY` last.
  tools/search-validate.sh POLICY [POLICY ...]
"""


def search_validate(policies, episodes="50", seed="1000000"):
    os.chdir(ROOT)
    agvrl = agvrl_bin(build=True)
    scores = []
    for policy in policies:
        total = bare = 0
        coverage = []
        for _env, _layouts, _preset, args in search_rows(policy, episodes, seed):
            r = report([agvrl] + args)
            total += r["collisions"]
            coverage.append(printed(r, "coverage", 3))
            # The same episodes without the filter: reported beside the score, not part of the rule.
            bare += report([agvrl] + args + ["--safety-filter", "off"])["collisions"]
        mean = float(f"{sum(coverage) / len(coverage):.3f}")
        out(f"policy={policy} validation_terminations={total} validation_mean_coverage={mean:.3f} "
            f"validation_bare_terminations={bare} episodes=800")
        scores.append((policy, total, bare, mean))
    rows = [s for s in scores if s[1] <= min(s[1] for s in scores) + 2]
    rows = [s for s in rows if s[2] <= min(s[2] for s in rows) + 10]
    out("picked=" + max(rows, key=lambda s: s[3])[0])


RACE_TABLE = """\
The self-play results of docs/racing.md for one duel policy: DUEL against LONE (a single-car
policy) on both shipped tracks, DUEL against itself, and both policies alone (lap times).
Usage: tools/race-table.sh DUEL.agvrl LONE.agvrl [RACES] [SEED]
Every car's line of `agvrl race`, after the row's label (width bands are not printed).
"""

# The paper's racing rules on the tracks, the rules docs/racing.md's self-play figures were
# measured under (a map track's own default is contact only with a progress reward).
RULES = ["--set", "env_config.racing.end_below_m=0.8", "--set", 'env_config.racing.reward="paper"',
         "--set", "env_config.racing.crash_penalty=-50.0",
         "--set", "env_config.racing.stall_after_s=0.0"]


def car_line(c):
    """One car's figures as `agvrl race` prints them (CarFigures::line)."""
    n = float(max(c["races"], 1))

    def opt(v, d=2):
        return "none" if v is None else f"{v:.{d}f}"

    def share(a, b):
        return a / b if b > 0 else None

    crashes_per_km = c["crashes"] / c["covered_km"] if c["covered_km"] > 0 else None
    return (
        f"car={c['car']} policy={c['policy']} races={c['races']} wins={c['wins']} "
        f"win_rate={c['wins'] / n:.2f} mean_place={c['mean_place']:.2f} "
        f"laps_per_race={c['laps_per_race']:.2f} mean_lap_s={opt(c['mean_lap_s'])} "
        f"best_lap_s={opt(c['best_lap_s'])} encounters={c['encounters']} passes={c['passes']} "
        f"pass_success={opt(share(c['passes'], c['encounters']))} "
        f"races_with_pass={c['races_with_pass']} "
        f"races_with_pass_share={opt(share(c['races_with_pass'], c['races']))} "
        f"at_fault_incidents={c['at_fault_incidents']} "
        f"at_fault_share={opt(share(c['at_fault_incidents'], c['passes'] + c['at_fault_incidents']))} "
        f"starts_behind={c['starts_behind']} wins_from_behind={c['wins_from_behind']} "
        f"win_rate_from_behind={opt(share(c['wins_from_behind'], c['starts_behind']))} "
        f"contacts_per_race={c['contacts'] / n:.2f} "
        f"at_fault_per_race={c['at_fault_contacts'] / n:.2f} "
        f"time_lost_s_per_race={c['time_lost_s'] / n:.2f} crashes={c['crashes']} "
        f"covered_km={c['covered_km']:.2f} crashes_per_km={opt(crashes_per_km, 3)}")


def race_table(duel, lone, races, seed):
    agvrl = agvrl_bin(build=False)

    def row(label, *args):
        r = report([agvrl, "race", *args, *RULES, "--races", races, "--seed", seed])
        for c in r["figures"]:
            out(f"{label} {car_line(c)}")

    for t in ("bean", "sweepers"):
        track = ["--track", f"assets/tracks/{t}.yaml"]
        row(f"vs-lone track={t}", "--policy", duel, "--policy", lone, *track)
        row(f"self track={t}", "--policy", duel, *track)
        row(f"alone track={t}", "--policy", duel, "--cars", "1", *track)
        row(f"lone-alone track={t}", "--policy", lone, "--cars", "1", *track)


def main(argv=None):
    text = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(prog="tools/tables.py", description=__doc__,
                                     formatter_class=text)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("search-table", description=SEARCH_TABLE, formatter_class=text,
                       help="a policy against the uniform random policy (tools/search-table.sh)")
    p.add_argument("policy", nargs="?", default="", metavar="POLICY")
    p.add_argument("episodes", nargs="?", default="", metavar="EPISODES")
    p.add_argument("seed", nargs="?", default="", metavar="SEED")
    p.add_argument("filter", nargs="?", default="", metavar="FILTER")

    p = sub.add_parser("search-safety-table", description=SEARCH_SAFETY_TABLE,
                       formatter_class=text,
                       help="the bare and the filtered policy, frontier and map planner "
                            "(tools/search-safety-table.sh)")
    p.add_argument("policy", nargs="?", default="", metavar="POLICY")
    p.add_argument("episodes", nargs="?", default="", metavar="EPISODES")
    p.add_argument("seed", nargs="?", default="", metavar="SEED")

    p = sub.add_parser("search-validate", description=SEARCH_VALIDATE, formatter_class=text,
                       help="the validation score that picks which training ships "
                            "(tools/search-validate.sh)")
    p.add_argument("policies", nargs="+", metavar="POLICY")

    p = sub.add_parser("race-table", description=RACE_TABLE, formatter_class=text,
                       help="the self-play results of docs/racing.md (tools/race-table.sh)")
    p.add_argument("duel", metavar="DUEL.agvrl")
    p.add_argument("lone", metavar="LONE.agvrl")
    p.add_argument("races", nargs="?", default="100", metavar="RACES")
    p.add_argument("seed", nargs="?", default="1000", metavar="SEED")

    a = parser.parse_args(argv)
    # As the scripts' ${1:-default}: an empty argument takes the default.
    if a.command == "search-table":
        search_table(a.policy or DEFAULT_POLICY, a.episodes or "100", a.seed or "0", a.filter)
    elif a.command == "search-safety-table":
        search_safety_table(a.policy or DEFAULT_POLICY, a.episodes or "100", a.seed or "0")
    elif a.command == "search-validate":
        search_validate(a.policies)
    else:
        race_table(a.duel, a.lone, a.races or "100", a.seed or "1000")


if __name__ == "__main__":
    main()
