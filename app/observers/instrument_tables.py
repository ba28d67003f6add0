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
