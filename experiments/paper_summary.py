"""The paper's Tables 1-3 and Figures 2-4 over every environment with committed results, side by side with the
paper's numbers, and per row whether the paper's claim holds here. Reads the experiments' committed outputs;
trains nothing.

    PYTHONPATH=. python experiments/paper_summary.py [--results results] [--out results/paper]

Sources: continuous DST from ``results/cdst_moiq/`` (``best_models.csv``; beta 5 from ``beta_sweep_ups2.txt``;
learning curves ``curves.npz``); each MuJoCo task, under every protocol found, from its per-task outputs
``results/mujoco_<protocol>/<env>/<name>/`` where they exist, else from the all-task ones
``results/mujoco_<protocol>/<name>/`` (``name``: table1-3, figure2-4), with the rows of ``<env>/<name>_more_seeds/``
(the same command over more seeds of some betas) in place of theirs, and the rows of ``<env>/table{1,3}_rerun/``
(the same command over ``runs_rerun/``, a second set of runs of the same seeds) beside them as protocol
``<protocol> rerun``. Writes ``table{1,2,3}.csv``,
``figure{2,3,4}.csv`` and ``summary.md`` under ``--out``. The claims checked per row: Table 1, MOIQ's best model
within 10% of the expert's return, ``moiq >= expert - 0.1 |expert|`` (the paper's MOIQ column is, in 12 of 15
settings; ``claim_holds_each_best`` judges each preference's own best actor where the runs kept it); Table 2,
beta = 5 ahead of beta = 0 where the paper found it ahead (and behind where it found it behind); Table 3, a
correlation at least the paper's (in each reading: ``claim_holds`` per step on the demonstrations,
``claim_holds_episodes`` across the best model's own episodes); Figures 2 and 4, MOIQ at beta = 5 ending within
10% of the baseline or above it. Figure 3's hypervolumes are reported against the experts' (the paper gives no number).
"""

from __future__ import annotations

import argparse
import csv
import json
import pathlib
import subprocess

import numpy as np
import paper_mujoco as paper

from moiq_jax.experts.sac import PAPER_EXPERT_RETURNS

CDST_PREFERENCES = ((0.9, 0.1), (0.5, 0.5), (0.1, 0.9))
# The paper's continuous DST rows (its Tables 1 and 2); its Table 3 has no continuous DST row.
PAPER_CDST = {"moiq": (20.03, 5.05, -1.73), "expert": (20.03, 5.05, -1.73),
              "beta0": (19.96, 5.044, -1.736), "beta5": (19.927, 5.044, -1.736)}
PAPER_TABLE1_EXPERT = {**{env: PAPER_EXPERT_RETURNS[env] for env in paper.TASKS}, "cdst": PAPER_CDST["expert"]}
PAPER_TABLE1_MOIQ = {**paper.PAPER_TABLE1, "cdst": PAPER_CDST["moiq"]}


def cdst_rows(results: pathlib.Path) -> tuple[list[dict], list[dict]]:
    """Continuous DST's Table 1 rows (the best models of ``experiments/cdst_moiq.py`` at beta 0.5 and of the
    beta sweep at the paper's 5) and Table 2 rows (EWMA return at the end, beta 0 and 0.5; beta 5's curves
    were not kept)."""
    folder = results / "cdst_moiq"
    if not (folder / "best_models.csv").exists():
        return [], []
    with open(folder / "best_models.csv") as f:
        best = [r for r in csv.DictReader(f)]
    sweep = json.loads((folder / "beta_sweep_ups2.txt").read_text().splitlines()[-1])
    table1 = []
    for e, w in enumerate(CDST_PREFERENCES):
        expert = float(next(r["expert_scalarised_return"] for r in best if json.loads(r["preference"]) == list(w)))
        by_beta = {0.5: [float(r["scalarised_return"]) for r in best
                         if r["method"] == "MOIQ beta=0.5" and json.loads(r["preference"]) == list(w)]}
        by_beta[5.0] = [run["scalar"][e] for name, run in sweep.items() if name.startswith("5.0-")]
        for beta, returns in by_beta.items():
            table1.append(table1_row("cdst", list(w), beta, np.mean(returns), np.std(returns), expert, len(returns),
                                     "cdst_moiq"))
    curves = np.load(folder / "curves.npz")
    table2 = []
    last = paper.last_window_mean(curves["MOIQ beta=0/env_steps"][0], curves["MOIQ beta=0/eval_scalar_return"])
    for e, w in enumerate(CDST_PREFERENCES):
        final = {beta: float(paper.ewma(curves[f"MOIQ beta={beta}/eval_scalar_return"], axis=1)[:, -1, e].mean())
                 for beta in ("0", "0.5")}
        table2.append({"env": "cdst", "preference": list(w), "protocol": "cdst_moiq",
                       "seeds": len(curves["MOIQ beta=0/eval_scalar_return"]), "beta0": round(final["0"], 3),
                       "beta5": None, "beta0.5": round(final["0.5"], 3), "beta0_last": round(float(last[:, e].mean()), 3),
                       "beta5_last": None, "paper_beta0": PAPER_CDST["beta0"][e],
                       "paper_beta5": PAPER_CDST["beta5"][e], "claim_holds": None})
    return table1, table2


def table1_row(env, preference, beta, mean, std, expert, seeds, protocol, demos=None, each_best=None) -> dict:
    """One Table 1 row; ``each_best``: the mean return of each seed's own best actor for this preference (the
    per-preference reading of "the best model"; None where the runs did not keep it), judged beside the one model."""
    e = [tuple(w) for w in paper_preferences(env)].index(tuple(preference))
    ratio = mean / expert  # shown; the claim is judged by the difference, which negative returns keep meaningful
    return {"env": env, "preference": preference, "beta": beta, "protocol": protocol, "moiq": round(float(mean), 2),
            "moiq_std": round(float(std), 2), "expert": round(float(expert), 2), "ratio": round(float(ratio), 3),
            "seeds": seeds, "paper_moiq": PAPER_TABLE1_MOIQ[env][e], "paper_expert": PAPER_TABLE1_EXPERT[env][e],
            "demos": demos, "claim_holds": paper.near_expert(mean, expert),
            "each_best": None if each_best is None else round(float(each_best), 2),
            "claim_holds_each_best": None if each_best is None else paper.near_expert(each_best, expert)}


def paper_preferences(env: str):
    return CDST_PREFERENCES if env == "cdst" else paper.moiq_config(env).preferences


def outputs_by_env(folder: pathlib.Path, name: str) -> dict[str, dict]:
    """Each MuJoCo task's record of output ``name`` (``table1`` ... ``figure4``) under one protocol's folder: its
    per-task run ``<env>/<name>/<name>.json`` where there is one, else the all-task run ``<name>/<name>.json``."""
    sources = {}
    for env in paper.TASKS:
        for path in (folder / env / name / f"{name}.json", folder / name / f"{name}.json"):
            if path.exists():
                sources[env] = json.loads(path.read_text())
                break
    return sources


def env_rows(folder: pathlib.Path, name: str) -> list[dict]:
    """The rows of output ``name`` under ``folder``, each task's from its source (``outputs_by_env``), each with
    ``demos``: whether it was made from the committed demonstrations (``demos_of``), and ``seeds``: the output's
    seed count where a row does not give its own. A task's ``<env>/<name>_more_seeds/<name>.json`` (the same
    command over more seeds of some betas) replaces the rows of the same preference and beta that it averages
    over more seeds."""
    setting = lambda r: (str(r["preference"]), r.get("beta"))
    rows = []
    for env, record in outputs_by_env(folder, name).items():
        own = record_rows(env, record)
        more_seeds = folder / env / f"{name}_more_seeds" / f"{name}.json"
        if more_seeds.exists():
            more = {setting(r): r for r in record_rows(env, json.loads(more_seeds.read_text()))}
            own = [max((r, more.get(setting(r), r)), key=lambda x: x["seeds"] or 0) for r in own]  # ties keep r
        rows += own
    return rows


def rerun_rows(folder: pathlib.Path, name: str) -> list[dict]:
    """The rows of each task's ``<env>/<name>_rerun/<name>.json`` under ``folder``: the same command over a second
    set of runs of the same seeds (the protocol's ``runs_rerun/``; a second sample wherever those runs are not
    bit-identical to the main ones), kept beside the main rows and counted apart from them."""
    rows = []
    for env in paper.TASKS:
        path = folder / env / f"{name}_rerun" / f"{name}.json"
        if path.exists():
            rows += record_rows(env, json.loads(path.read_text()))
    return rows


def labelled_rows(folder: pathlib.Path, protocol: str, name: str) -> list[tuple[str, dict]]:
    """``(protocol label, row)`` for output ``name``'s main rows (``env_rows``) and then its rerun rows
    (``rerun_rows``), which are labelled ``<protocol> rerun`` so that they are counted apart."""
    return [(protocol, r) for r in env_rows(folder, name)] + [(f"{protocol} rerun", r) for r in rerun_rows(folder, name)]


def record_rows(env: str, record: dict) -> list[dict]:
    """Task ``env``'s rows of one output record, with ``seeds`` and ``demos`` (see ``env_rows``)."""
    demos = demos_of(env, record)
    return [{"seeds": record.get("seeds"), **r, "demos": demos} for r in record.get("rows", []) if r["env"] == env]


def demos_of(env: str, record: dict) -> str | None:
    """``"committed"`` if output ``record`` of ``env`` was made from the committed demonstrations, ``"replaced"`` if
    from earlier ones (an expert's demonstrations replaced since leave its runs' figures about other experts), None
    if it cannot tell. Judged by git, where the record names the commit that wrote it (was the task's demonstrations
    file changed since?), else by its Table 1 rows' expert returns against the committed demonstrations'."""
    commit = (record.get("provenance") or {}).get("commit")
    if commit:
        changed = subprocess.run(["git", "-C", str(paper.ROOT), "log", "--format=%H", f"{commit}..HEAD", "--",
                                  f"experiments/demos/{env}.npz"], capture_output=True, text=True, check=False)
        if changed.returncode == 0:
            return "replaced" if changed.stdout.strip() else "committed"
    rows = [r for r in record.get("rows", []) if r.get("env") == env and "expert" in r]
    if not rows:
        return None
    preferences = np.asarray(paper_preferences(env))
    experts = (paper.expert_returns(env) * preferences).sum(1)  # [E]: each expert under its own preference
    expert_of = dict(zip(map(tuple, preferences.tolist()), experts))
    return "committed" if all(abs(r["expert"] - expert_of[tuple(r["preference"])]) <= 0.01 + 1e-6 * abs(r["expert"])
                              for r in rows) else "replaced"


def mujoco_rows(results: pathlib.Path) -> tuple[list[dict], list[dict], list[dict]]:
    """Tables 1-3 rows of every MuJoCo task and protocol with committed outputs."""
    table1, table2, table3 = [], [], []
    for folder in sorted(results.glob("mujoco_*")):
        protocol = folder.name.removeprefix("mujoco_")
        for label, r in labelled_rows(folder, protocol, "table1"):
            table1.append(table1_row(r["env"], r["preference"], r["beta"], r["moiq_mean"], r["moiq_std"], r["expert"],
                                     r["seeds"], label, r["demos"], r.get("each_best_mean")))
        for r in env_rows(folder, "table2"):
            paper_better = r["paper_beta5"] > r["paper_beta0"]
            table2.append({"env": r["env"], "preference": r["preference"], "protocol": protocol, "seeds": r["seeds"],
                           "beta0": r["beta0"],
                           "beta5": r["beta5"], "beta0.5": r.get("beta0.5"), "beta0_last": r.get("beta0_last"),
                           "beta5_last": r.get("beta5_last"), "paper_beta0": r["paper_beta0"],
                           "paper_beta5": r["paper_beta5"], "demos": r["demos"],
                           "claim_holds": (r["beta5"] > r["beta0"]) == paper_better})
        for label, r in labelled_rows(folder, protocol, "table3"):
            episode = r.get("episode_correlation")  # outputs written before the episode reading have none
            table3.append({"env": r["env"], "preference": r["preference"], "beta": r["beta"], "protocol": label,
                           "seeds": r["seeds"],
                           "correlation": r["correlation"], "std": r["std"],
                           "per_objective": [round(float(c), 3) for c in r["per_objective"]],
                           "episode_correlation": episode, "paper": r["paper"], "demos": r["demos"],
                           "claim_holds": r["correlation"] >= r["paper"],
                           "claim_holds_episodes": None if episode is None else episode >= r["paper"]})
    return table1, table2, table3


def learning_curve_rows(results: pathlib.Path, name: str, baseline: str) -> list[dict]:
    """Figure 2 (``baseline`` GAIL) or Figure 4 (IQ-Learn) rows: the final EWMA return of MOIQ at each beta and
    of the baseline per task and preference. The claim judged: MOIQ at the paper's beta ends within 10% of the
    baseline or above it (Figure 2: "competitive with GAIL"; Figure 4: IQ-Learn unstable where MOIQ grows)."""
    rows, moiq = [], f"MOIQ beta={paper.PAPER_BETA:g}"
    for folder in sorted(results.glob("mujoco_*")):
        protocol = folder.name.removeprefix("mujoco_")
        for env, record in outputs_by_env(folder, name).items():
            last_of_env = record.get("final_last_window_return", {}).get(env, {})
            demos = demos_of(env, record)
            for preference, final in record["final_ewma_return"].get(env, {}).items():
                last = last_of_env.get(preference, {})
                rows.append({"env": env, "preference": json.loads(preference), "protocol": protocol,
                             "seeds": record["seeds"], "demos": demos,
                             **{method.lower(): value for method, value in final.items()},
                             **{f"{method.lower()}_last": last.get(method) for method in final},
                             "claim_holds": paper.near_expert(final[moiq], final[baseline]),
                             "claim_holds_last": paper.near_expert(last[moiq], last[baseline]) if last else None})
    return rows


def transfer_rows(results: pathlib.Path) -> list[dict]:
    """Figure 3 rows: per task and beta, the hypervolume of MOIQ's transferred front (mean and spread over seeds)
    against the experts' front, with the same reference point."""
    rows = []
    for folder in sorted(results.glob("mujoco_*")):
        protocol = folder.name.removeprefix("mujoco_")
        for env, record in outputs_by_env(folder, "figure3").items():
            if env not in record:
                continue
            expert, demos = record[env]["expert_hypervolume"], demos_of(env, record)
            for beta, volumes in record[env]["hypervolume_per_seed"].items():
                rows.append({"env": env, "beta": float(beta.removeprefix("beta=")), "protocol": protocol,
                             "seeds": len(volumes), "demos": demos, "hypervolume": round(float(np.mean(volumes)), 2),
                             "hypervolume_std": round(float(np.std(volumes)), 2), "expert_hypervolume": expert,
                             "ratio": round(float(np.mean(volumes)) / expert, 4)})
    return rows


def write_csv(path: pathlib.Path, rows: list[dict]) -> None:
    if rows:
        with open(path, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(dict.fromkeys(k for r in rows for k in r)))
            writer.writeheader()
            writer.writerows(rows)


def markdown(title: str, rows: list[dict], columns: list[str]) -> list[str]:
    """One markdown table of ``rows`` (a cell of None, a value not recorded, is shown as "n/a") and the count of
    rows where the paper's claim holds, over the rows not made from replaced demonstrations."""
    cell = lambda v: "n/a" if v is None else ("yes" if v is True else "no" if v is False else str(v))
    lines = [f"## {title}", "", "| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(cell(r.get(c)) for c in columns) + " |" for r in rows]
    held = [r["claim_holds"] for r in rows if r.get("claim_holds") is not None and r.get("demos") != "replaced"]
    stale = sum(r.get("demos") == "replaced" for r in rows)
    count = f"The paper's claim holds in {sum(held)} of {len(held)} rows checked" + (
        f" (not counted: {stale} rows made from demonstrations since replaced)." if stale else ".")
    return lines + (["", count] if held else []) + [""]


def claims_by_protocol(rows: list[dict], claim: str = "claim_holds") -> list[str]:
    """Per protocol and beta: in how many settings (task, preference) the claim holds (``claim``: the rows'
    column saying so), over which tasks; rows made from replaced demonstrations or without that column left out."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        if r.get("demos") != "replaced" and r.get(claim) is not None:
            groups.setdefault((r["protocol"], r["beta"]), []).append(r)
    lines = ["| protocol | beta | settings where the claim holds | tasks |", "|---|---|---|---|"]
    for (protocol, beta), group in groups.items():
        tasks = ", ".join(dict.fromkeys(r["env"] for r in group))
        lines.append(f"| {protocol} | {beta:g} | {sum(r[claim] for r in group)} of {len(group)} | {tasks} |")
    return lines + [""]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", default="results")
    parser.add_argument("--out", default="results/paper")
    args = parser.parse_args()
    results, out = pathlib.Path(args.results), pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cdst1, cdst2 = cdst_rows(results)
    mujoco1, mujoco2, table3 = mujoco_rows(results)
    table1, table2 = cdst1 + mujoco1, cdst2 + mujoco2
    figure2 = learning_curve_rows(results, "figure2", "GAIL")
    figure3 = transfer_rows(results)
    figure4 = learning_curve_rows(results, "figure4", "IQ-Learn")
    for name, rows in (("table1", table1), ("table2", table2), ("table3", table3), ("figure2", figure2),
                       ("figure3", figure3), ("figure4", figure4)):
        write_csv(out / f"{name}.csv", rows)
    lines = ["# The paper's tables beside this project's measurements", "",
             "Written by `PYTHONPATH=. python experiments/paper_summary.py` from the committed outputs named in its",
             "docstring; `protocol` says which run each row comes from (cdst_moiq: `results/cdst_moiq/`, its tuned",
             "config; cpu / cpu_recipe / paper: `experiments/paper_mujoco.py`'s protocols; `<protocol> rerun`: the same",
             "command's second set of runs of the same seeds, `runs_rerun/`, counted apart). `demos`: whether a MuJoCo",
             "row was made from the committed demonstrations (`replaced`: from experts replaced since, so not counted",
             "in the claims; n/a: the output does not say).", ""]
    lines += markdown("Table 1: best model's scalarised return (claim: within 10% of the expert)", table1,
                      ["env", "preference", "beta", "protocol", "moiq", "moiq_std", "expert", "ratio", "seeds",
                       "paper_moiq", "paper_expert", "demos", "claim_holds", "each_best", "claim_holds_each_best"])
    lines += ["One model per run (`moiq`, `claim_holds`; the count above):", ""] + claims_by_protocol(table1)
    lines += ["Each preference's own best actor (`each_best`, `claim_holds_each_best`; runs that kept it):", ""]
    lines += claims_by_protocol(table1, "claim_holds_each_best")
    lines += markdown("Table 2: EWMA return at the end, beta 0 against 5 (claim: the paper's ordering; `_last`: mean "
                      "return over the last 20% of training, which the EWMA of a short run does not weigh alone)", table2,
                      ["env", "preference", "protocol", "seeds", "beta0", "beta5", "beta0.5", "beta0_last", "beta5_last",
                       "paper_beta0", "paper_beta5", "demos", "claim_holds"])
    lines += markdown("Table 3: Pearson correlation of recovered and true scalarised reward (claim: >= the paper's; "
                      "`correlation`: per step on the demonstrations; `episode_correlation`: of the episode returns "
                      "across the best model's own episodes, the measure of IQ-Learn's code, on which the paper's is "
                      "built; `claim_holds_episodes`: the claim on that reading)",
                      table3, ["env", "preference", "beta", "protocol", "seeds", "correlation", "std", "per_objective",
                               "episode_correlation", "paper", "demos", "claim_holds", "claim_holds_episodes"])
    lines += ["Per step on the demonstrations:", ""] + claims_by_protocol(table3)
    lines += ["Across the best models' own episodes:", ""] + claims_by_protocol(table3, "claim_holds_episodes")
    moiq_columns = [f"moiq beta={beta:g}{end}" for end in ("", "_last") for beta in paper.MOIQ_BETAS]
    lines += markdown("Figure 2: EWMA return at the end, MOIQ against GAIL (claim: MOIQ at beta 5 within 10% of GAIL "
                      "or above; `_last`: mean return over the last 20% of training)", figure2,
                      ["env", "preference", "protocol", "seeds", *moiq_columns, "gail", "gail_last", "demos", "claim_holds",
                       "claim_holds_last"])
    lines += markdown("Figure 3: hypervolume of the transferred front over 19 preferences against the experts'",
                      figure3, ["env", "beta", "protocol", "seeds", "hypervolume", "hypervolume_std",
                                "expert_hypervolume", "ratio", "demos"])
    lines += markdown("Figure 4: EWMA return at the end from 1 demonstration per preference, MOIQ against IQ-Learn "
                      "(claim: MOIQ at beta 5 within 10% of IQ-Learn or above)", figure4,
                      ["env", "preference", "protocol", "seeds", *moiq_columns, "iq-learn", "iq-learn_last", "demos", "claim_holds",
                       "claim_holds_last"])
    (out / "summary.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
