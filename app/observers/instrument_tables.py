"""The instrument check's results as text: what `tomstudy instrument` prints, and the verdict
line `tomstudy bundle build` prints per bank (app/observers/simulated_study.py runs it)."""


def pass_rate(rate: float | None) -> str:
    """A pass rate for the instrument table ("-" without replications)."""
    return f"{rate:>9.2f}" if rate is not None else f"{'-':>9}"


def instrument_table(summary: dict, alpha: float, replications: int) -> list[str]:
    """Per world and lane reading: both populations' mean difference, Welch's test, the
    verdict and the pass rate; then what the columns mean."""
    lines = [f"{'world':<14}{'reading':<10}{'coarse':>9}{'precise':>9}{'t':>8}{'p':>10}"
             f"  result  pass rate"]
    for row in summary["rows"]:
        verdict = "pass" if row["passed"] else "FAIL"
        lines.append(f"{row['world']:<14}{row['reading']:<10}{row['coarse_mean_diff']:>+9.3f}"
                     f"{row['precise_mean_diff']:>+9.3f}{row['welch_t']:>8.2f}"
                     f"{row['p_one_sided']:>10.2g}  {verdict:<6}  {pass_rate(row['pass_rate'])}")
    lines.append("coarse/precise = mean err_ours - err_vae per population; "
                 f"pass = Welch one-sided p < {alpha};\npass rate = share of {replications} "
                 "reruns with fresh simulated participants that pass")
    return lines


def separation_table(rows: list[dict]) -> list[str]:
    """What the metric can tell apart, per world and start kind."""
    lines = [f"\n{'world':<14}{'start kind':<15}{'starts':>7}{'ours-vae':>10}"
             f"{'obs gap':>9}{'coarse':>9}{'precise':>9}"]
    for row in rows:
        lines.append(f"{row['world']:<14}{row['start_kind']:<15}{row['n_starts']:>7}"
                     f"{row['ours_vs_vae']:>10.3f}{row['coarse_vs_precise']:>9.3f}"
                     f"{row['coarse_diff']:>+9.4f}{row['precise_diff']:>+9.4f}")
    lines.append("ours-vae / obs gap = mean 1-cos between the two models' answers / the two "
                 "observers' clicks\nat the same start states; coarse/precise = each observer's "
                 "err_ours - err_vae there")
    return lines


def verdict_line(name: str, summary: dict) -> str:
    """The instrument check's verdict and pass rate per world on the `name` bank."""
    verdicts = ", ".join(f"{world} {'pass' if ok else 'FAIL'} (pass rate "
                         f"{pass_rate(summary['pass_rate'][world]).strip()})"
                         for world, ok in summary["passed"].items())
    return f"instrument on the {name} bank: {verdicts}"


def goal_table(result: dict, exploratory: dict[str, str]) -> list[str]:
    """The design goal per world, arm and seed set: each variant's P(primary concludes Ours);
    then each world's verdict (exploratory worlds named with why) and the designs that would
    meet it."""
    variants = list(dict.fromkeys(row["variant"] for row in result["rows"]))
    lines = ["\ndesign goal: P(primary test concludes Ours) per observer, participants and "
             "trials random", f"{'world':<14}{'arm':<18}{'seeds':<17}"
             + "".join(f"{short(v):>10}" for v in variants) + f"{'old':>6}"]
    groups: dict[tuple, dict] = {}
    for row in result["rows"]:
        groups.setdefault((row["world"], row["arm"], row["seeds"]), {})[row["variant"]] = row
    for (world, arm, seeds), row in groups.items():
        old = row["coarse"]["participants_only_power"]
        lines.append(f"{world:<14}{arm:<18}{seeds:<17}"
                     + "".join(f"{row[v]['p_ours']:>10.2f}" for v in variants) + f"{old:>6.2f}")
    lines += goal_notes(result)
    lines += [goal_verdict(world, result["goal_met_by_seeds"][world], exploratory)
              for world in result["goal_met"]]
    lines += needed_lines(result["needed"])
    return lines


def short(variant: str) -> str:
    """A variant's column name."""
    return {"coarse": "straight", "coarse_scene": "scene", "coarse_momentum": "momentum",
            "constant_velocity": "cv"}.get(variant, variant)


def goal_notes(result: dict) -> list[str]:
    """What the goal table's numbers are."""
    d = result["design"]
    return [f"design: {d['participants']} participants, {d['bank_trials']} bank trials, "
            f"{d['trials_each']} each; {result['reps']} simulated studies per cell; primary = "
            f"family err_ours - err_vae, min F', two-sided alpha {result['alpha']}",
            f"goal: straight, scene, momentum >= {result['goal_power']}, precise <= "
            f"{result['alpha']} (arm all; the family, and the held-out family where the design "
            "read only some seeds); cv is reported, never tested; old = how often the earlier "
            "participants-only test (one-sided paired t) says Ours for the straight observer "
            "in the same simulated studies"]


def goal_verdict(world: str, met: dict[str, bool], exploratory: dict[str, str]) -> str:
    """One world's line: meets the goal (and whether held-out seeds confirm it), misses it, or
    exploratory and why."""
    words = "meets the goal" if met["family"] else "MISSES the goal"
    if "held-out family" in met:
        words += (", confirmed on the held-out seeds" if met["held-out family"]
                  else ", NOT CONFIRMED on the held-out seeds")
    if world in exploratory:
        return f"{world}: EXPLORATORY ({words}): {exploratory[world]}"
    return f"{world}: {words}"


def needed_lines(needed: list[dict]) -> list[str]:
    """Per world and bank size, the fewest participants that meet the goal."""
    if not needed:
        return []
    lines = ["participants needed to meet the goal on the family and the held-out family "
             "(bank trials: participants; - = none within 240, or a precise observer "
             "concludes Ours):"]
    worlds = dict.fromkeys(row["world"] for row in needed)
    for world in worlds:
        cells = [f"{r['bank_trials']}: {r['participants_needed'] or '-'}" for r in needed
                 if r["world"] == world]
        lines.append(f"  {world:<14}" + ", ".join(cells))
    return lines
