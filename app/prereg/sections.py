"""The preregistration's sections, in the order of the OSF Preregistration template: study
information and hypotheses, design, sampling plan, variables, analysis plan, exclusions,
inference criteria, then the observer family, the deviations from the paper and the sources.

Every number is taken through the inputs' ledger (app/prereg/sources.py), so the Sources
table at the end names the file, key and SHA-256 it came from."""

from analysis.codebook import StudyTerms, column_entry
from app.bank.bundle import BANK, checkpoint_file
from app.observers.family import COARSE_VARIANTS, GOAL_VARIANTS
from app.prereg.document import Document, Items, Section, Table
from app.prereg.inputs import Inputs
from app.prereg.readme import readme_table
from app.prereg.sources import shown
from app.study.config import config_sha256, stored_predictors

# the paper's hypothesis H, as the paper states it (docs/reproduce/departures.md, "Where this
# implementation departs from the paper", lists how this platform tests it)
PAPER_HYPOTHESIS = ("Ours will more accurately match the predictions made by human "
                    "participants as compared to VAE.")
DEVIATIONS_HEADING = "# Where this implementation departs from the paper"
# the export columns a preregistration names as measured (app/core/contracts.py has them all)
# the predictions export's columns the analysis reads; their meaning is the codebook's
MEASURED_COLUMNS = (
    "participant_vx", "participant_vy", "participant_click_x", "participant_click_y",
    "ours_vx", "ours_vy", "vae_vx", "vae_vy", "cv_vx", "cv_vy", "policy_vx", "policy_vy",
    "coarse_vx", "coarse_vy", "coarse_scene_vx", "coarse_scene_vy", "coarse_momentum_vx",
    "coarse_momentum_vy", "world", "trial_id", "arm", "start_index", "start_kind", "step",
    "click_time_ms", "trial_duration_ms", "attention_passed", "completed", "outcome",
    "bank_sha256", "config_sha256",
)

def preregistration(inputs: Inputs) -> Document:
    """The whole document for one study."""
    roles = {world: world_role(inputs, world) for world in inputs.config.worlds}
    sections = (study_information(inputs), inputs_missing(inputs), design(inputs, roles),
                sampling_plan(inputs), variables(inputs), analysis_plan(inputs),
                exclusions(inputs), inference_criteria(inputs, roles), observer_family(inputs),
                deviations(inputs))
    kept = tuple(s for s in sections if s.blocks)
    return Document(f"Preregistration: {inputs.config.title} ({inputs.study_id})",
                    (*kept, sources(inputs)))


# -- study information and hypotheses


def study_information(inputs: Inputs) -> Section:
    """What the study is, the frozen bundle that defines it, and the hypotheses."""
    return Section("Study information and hypotheses", (
        f"Study `{inputs.study_id}`, served from the frozen bundle at "
        f"`{inputs.manifest.shown_path.removesuffix('/manifest.json')}`. This document is "
        "written from the study config, that bundle, the instrument check and the power "
        "simulation by `tomstudy prereg`; every number in it is listed with its file, key and "
        "SHA-256 under Sources.",
        bundle_table(inputs),
        checkpoint_table(inputs),
        f"**H (the paper's hypothesis):** {PAPER_HYPOTHESIS} Tested here per world as: the "
        "model family's mean alignment error of Ours (every training seed) is lower than the "
        "VAE family's, with participants and trials random (Analysis plan).",
        "The two accounts of how people predict, which the design tells apart (Design): people "
        "who predict through high-level patterns (the coarse observers) align better with "
        "Ours; people who predict precisely (the precise observer, the world's policy) align "
        "better with the VAE.",
        "**H2 (the direct test):** people's predictions align better with the coarse observers "
        "than with the precise one (the hypothesis asked without the two models as its proxy).",
    ))


def bundle_table(inputs: Inputs) -> Table:
    """The hashes that identify the study: bundle content, bank, configs."""
    take = inputs.ledger.take
    manifest = inputs.manifest
    rows = [("bundle content SHA-256", take(manifest, "content_sha256", "bundle content hash")),
            ("trial bank SHA-256 (its JSON; every export row's bank_sha256)",
             take(manifest, "bank_sha256", "trial bank hash")),
            (f"{BANK} file SHA-256", take(manifest, f"files.{BANK}.sha256", "bank file hash"))]
    for name in sorted(f for f in manifest.data["files"] if f.startswith("configs/")):
        rows.append((f"{name} SHA-256", take(manifest, f"files.{name}.sha256",
                                             f"frozen config {name}")))
    live = config_sha256(inputs.config)
    inputs.ledger.cite(inputs.study_config, "(canonical JSON of the validated config: "
                       "app/study/config.py config_sha256)", "live study config hash", live)
    rows.append(("live study config, canonical (every export row's config_sha256)", live))
    return Table(("what", "value"), tuple(rows))


def checkpoint_table(inputs: Inputs) -> Table:
    """Every checkpoint of the model family: its content hash and its file's SHA-256."""
    manifest = inputs.manifest.data
    rows = []
    for world, models in manifest["models"].items():
        for model, seeds in models.items():
            for seed, content in seeds.items():
                file = manifest["files"][checkpoint_file(world, model, int(seed))]["sha256"]
                rows.append((world, model, seed, content, file))
    inputs.ledger.cite(inputs.manifest, "models; files.models/*", "checkpoint hashes",
                       f"{len(rows)} checkpoints (table in Study information)")
    return Table(("world", "model", "seed", "content hash", "file SHA-256"), tuple(rows))


def inputs_missing(inputs: Inputs) -> Section:
    """Each input that is missing or ran on another bank, and the command that makes it."""
    problems = tuple(f"{r.name}: {r.problem}" for r in inputs.results() if r.problem)
    if not problems:
        return Section("Inputs not available", ())
    return Section("Inputs not available", (
        "These results are not in this document: where the text below needs one it says so. "
        "Run the command named and write the preregistration again.", Items(problems)))


# -- design


def design(inputs: Inputs, roles: dict[str, tuple[str, str]]) -> Section:
    """Within-participant design, the worlds and what each can test, trials, arms and starts."""
    return Section("Design", (
        procedure(inputs), worlds_table(inputs, roles), *goal_table(inputs), arms(inputs),
        trials_table(inputs), start_state_rule(inputs), models(inputs)))


def procedure(inputs: Inputs) -> str:
    """What each participant does, in numbers from the config."""
    s = inputs.setting
    worlds = s("worlds", "worlds")
    order = ("in counterbalanced order (half the participants the reverse)"
             if s("counterbalance_world_order", "world order counterbalanced") else "in order")
    return (f"Within participants: every participant takes every world ({shown(worlds)}) "
            f"{order}. Per world: {s('practice_trials', 'practice trials')} practice trial(s), "
            f"never analysed; {s('trials_per_world', 'scored trials per world')} scored trials; "
            f"{s('attention_checks.per_world', 'attention checks per world')} attention "
            f"check(s). A trial shows {s('examples_per_trial', 'example interactions')} "
            f"complete example interactions, then {s('segment_steps.min', 'segment steps min')}"
            f"-{s('segment_steps.max', 'segment steps max')} steps of a new one; the participant "
            f"predicts the robot's next {s('steps_to_predict', 'steps to predict')} moves from "
            f"each of {s('start_states', 'start states')} start states. "
            "Participants never see a model's answer.")


def world_role(inputs: Inputs, world: str) -> tuple[str, str]:
    """(confirmatory or exploratory, what the world can test) from the config and the design
    goal: a world the instrument finds missing the goal is exploratory whatever the config says."""
    marked = inputs.config.exploratory_worlds.get(world)
    met = goal_met(inputs, world)
    if marked:
        inputs.setting(f"exploratory_worlds.{world}", f"{world} exploratory (config)")
        return "exploratory", marked
    if met is False:
        return "exploratory", (
            "the instrument's design goal is missed here (goal.json goal_met false), yet the "
            "study config does not mark it exploratory; `tomstudy instrument` exits 1 for it: "
            "mark it in exploratory_worlds or change the design before any participant")
    if met is None:
        return "confirmatory (unchecked)", ("a test of the hypothesis if the design goal is "
                                            "met: not checked, the design goal result is "
                                            "not available")
    return "confirmatory", ("a test of the hypothesis: at the planned design every coarse "
                            "observer's primary test concludes Ours and the precise one's does "
                            "not (Design goal below)")


def goal_met(inputs: Inputs, world: str) -> bool | None:
    """Whether the design goal is met in `world` (None without a usable goal.json)."""
    if not inputs.goal.usable:
        return None
    return bool(inputs.ledger.take(inputs.goal.source, f"goal_met.{world}",
                                   f"design goal met in {world}"))


def worlds_table(inputs: Inputs, roles: dict[str, tuple[str, str]]) -> Table:
    """Per world: its kind, its role and what it can test, and the instrument check."""
    rows = []
    for world, (role, why) in roles.items():
        rows.append((world, world_kind(inputs, world), role, why, check_pass_rate(inputs, world)))
    return Table(("world", "kind", "role", "what it can test", "instrument check pass rate"),
                 tuple(rows))


def world_kind(inputs: Inputs, world: str) -> str:
    """simulated or recorded, from the bundle's frozen world config."""
    source = inputs.worlds[world]
    if "kind" in source.data:
        return inputs.ledger.take(source, "kind", f"{world} kind")
    inputs.ledger.cite(source, "kind (not set: simulated)", f"{world} kind", "simulated")
    return "simulated"


def check_pass_rate(inputs: Inputs, world: str) -> str:
    """The instrument check's pass rate in `world`, or why there is none."""
    if not inputs.instrument.usable:
        return f"not available (`{inputs.instrument.command}`)"
    rate = inputs.ledger.take(inputs.instrument.source, f"pass_rate.{world}",
                              f"instrument check pass rate, {world}")
    return shown(rate)


def goal_table(inputs: Inputs) -> tuple:
    """The design goal at the planned design: P(the primary test concludes Ours) per observer."""
    if not inputs.goal.usable:
        return (f"The design goal (would the primary test confirm the hypothesis at this "
                f"design?) is not available: run `{inputs.goal.command}`.",)
    source, take = inputs.goal.source, inputs.ledger.take
    want = take(source, "goal_power", "design goal power")
    alpha = take(source, "alpha", "design goal alpha")
    design_keys = ("participants", "bank_trials", "trials_each")
    planned = [take(source, f"design.{k}", f"design goal: {k}") for k in design_keys]
    rows = []
    for row in source.data["rows"]:
        if row["arm"] == "all" and row["seeds"] in ("family", "held-out family") and \
                row["participants"] == planned[0] and row["bank_trials"] == planned[1]:
            rows.append((row["world"], row["seeds"], row["variant"], shown(row["p_ours"]),
                         shown(row["p_vae"])))
    inputs.ledger.cite(source, "rows[arm=all, seeds=family|held-out family].p_ours, p_vae",
                       "design goal probabilities", f"{len(rows)} rows (table in Design)")
    return (f"**The design goal** (`tomstudy instrument`, before any participant): at the "
            f"planned design ({planned[0]} participants, {planned[1]} bank trials per world, "
            f"{planned[2]} each) every coarse observer's primary test concludes Ours with "
            f"probability >= {shown(want)} and the precise observer's with probability <= "
            f"{shown(alpha)}, on the model family (and on the held-out seeds' family where the "
            "design read only some seeds). "
            "P(Ours) and P(VAE) per observer from simulated studies:",
            Table(("world", "seeds", "observer", "P(concludes Ours)", "P(concludes VAE)"),
                  tuple(rows)))


def arms(inputs: Inputs) -> str:
    """The main-trial selection rule in words."""
    s = inputs.setting
    rule = s("main_trial_selection.rule", "main trial selection rule")
    bank = s("bank_trials_per_world", "bank trials per world")
    seed = s("bank_seed", "bank seed")
    text = (f"Main trials: each world's bank holds {bank} main trials (held-out segments, bank "
            f"seed {seed}); each participant sees {inputs.config.trials_per_world} of them, "
            "least seen first, each arm in proportion to its size. ")
    if rule == "random":
        return text + "Every main trial is in the random arm: the first usable segments."
    random_arm = s("main_trial_selection.random_arm_trials", "random arm trials")
    candidates = s("main_trial_selection.candidates_per_trial", "candidates per trial")
    text += (f"Two arms: `random`, the first {random_arm} usable segments, robot labels taking "
             f"turns; `{rule}`, the rest, chosen per robot label from {candidates} times as "
             "many further usable segments as the trials ")
    if rule == "models_disagree":
        return text + ("where the Ours and VAE families disagree most (mean 1 - cos over "
                       "every seed pair); it reads the models' answers only.")
    selection = s("main_trial_selection.selection_seeds", "selection seeds")
    return text + ("where the hypotheses differ most: the smallest, over the coarse observers, "
                   "of the precise observer's expected family err_ours - err_vae minus the "
                   f"coarse one's, on model seeds {shown(selection)} only (the others confirm "
                   "the design); it reads the observers' expected answers and those seeds' "
                   "models, never a participant's.")


def trials_table(inputs: Inputs) -> Table:
    """Per world, from the frozen bank's meta: trials by kind, arm sizes and start kinds."""
    take, meta = inputs.ledger.take, inputs.bank_meta
    rows = []
    for world in inputs.config.worlds:
        trials = take(meta, f"worlds.{world}.trials", f"{world} bank trials by kind")
        arm_sizes = take(meta, f"worlds.{world}.main_trial_selection.arms", f"{world} arm sizes")
        kinds = take(meta, f"worlds.{world}.main_start_kinds", f"{world} start kinds")
        rows.append((world, shown(trials["main"]), counts(arm_sizes), shown(trials["practice"]),
                     shown(trials["attention"]), counts(kinds)))
    return Table(("world", "main trials", "arms", "practice", "attention checks",
                  "start states by kind (main trials)"), tuple(rows))


def counts(mapping: dict) -> str:
    """{'a': 1, 'b': 2} as 'a 1, b 2'."""
    return ", ".join(f"{key} {shown(value)}" for key, value in mapping.items())


def start_state_rule(inputs: Inputs) -> str:
    """The start-state rule in words (app/bank/start_states.py)."""
    k = inputs.config.start_states
    return (f"Start states (`app/bank/start_states.py`): of a trial's {k}, the first is the "
            f"robot's own segment end (`own`); the other {k - 1} are robot positions in the "
            "data the models learned from (never a held-out future), each at least one "
            "reachable radius from the starts already chosen, the world's two kinds taking "
            "turns (kinds above), each turn a seeded uniform draw among that kind's points. In "
            "a simulated world every start keeps the segment end's heading and speed and the "
            "world's policy answers it; in a recorded world a relocated start is the recorded "
            "state it was drawn from, answered by what that car did next. Attention checks get "
            "their start states by the same rule.")


def models(inputs: Inputs) -> str:
    """The model family and the other predictors the bank answers with."""
    seeds = inputs.ledger.take(inputs.manifest, "seeds", "model family seeds")
    others = ", ".join(stored_predictors(inputs.config))
    return (f"Predictors: Ours and the VAE, each a family of training seeds {shown(seeds)} "
            f"(seed {seeds[0]} the primary, whose answers fill the live export's ours_* and "
            f"vae_* columns), constant velocity, the world's policy and {others}; every seed's "
            "answers are stored in the bank and recomputed by `tomstudy bundle verify`.")


# -- sampling plan


def sampling_plan(inputs: Inputs) -> Section:
    """The planned N and trials, where the number comes from, and the power simulation."""
    s = inputs.setting
    n = s("target_sample_size", "planned participants")
    platform = s("recruitment.platform", "recruitment platform")
    cap = inputs.config.recruitment.max_counted_sessions
    stop = ("`recruitment.max_counted_sessions` is not set: the researcher closes the study "
            "(`recruitment.closed`)")
    if cap:
        stop = ("the server turns new participants away once "
                f"{s('recruitment.max_counted_sessions', 'session cap')} sessions count")
    return Section("Sampling plan", (
        f"Planned sample: **{n} participants** recruited on {platform}, each taking "
        f"{inputs.config.trials_per_world} scored trials per world from the bank's "
        f"{inputs.config.bank_trials_per_world}. Researcher preview sessions are pilots and "
        f"never count; {stop}.",
        "Participants and trials are both random factors: the primary test (min F') "
        "generalises over people and over clips, and the simulations below draw each study's "
        "trials with replacement from the bank's main trials as well as its participants.",
        *sample_size_source(inputs, n), *power_lines(inputs)))


def sample_size_source(inputs: Inputs, n: int) -> tuple:
    """Where the planned N comes from: the design goal's search at the bank's size."""
    if not inputs.goal.usable:
        return (f"Where {n} comes from cannot be shown here: the design goal's search is not "
                f"available (run `{inputs.goal.command}`).",)
    source, bank = inputs.goal.source, inputs.config.bank_trials_per_world
    rows = [(r["world"], shown(r["participants_needed"] if r["participants_needed"] is not None
                               else "none up to the search's largest sample"))
            for r in source.data["needed"] if r["bank_trials"] == bank]
    inputs.ledger.cite(source, f"needed[bank_trials={bank}].participants_needed",
                       "participants needed per world", "; ".join(f"{w} {v}" for w, v in rows))
    return (f"Where the number comes from: the design goal's search (`{inputs.goal.command}`, "
            f"goal.json `needed`): the fewest participants with which the goal is met at "
            f"{bank} bank trials per world:",
            Table(("world", "participants needed"), tuple(rows)))


def power_lines(inputs: Inputs) -> tuple:
    """Per coarse observer, the n the power simulation needs for power 0.8, or how to get it."""
    rows, missing = [], []
    for kind, result in inputs.power.items():
        if not result.usable:
            missing.append(f"`{result.command}`")
            continue
        for world in inputs.config.worlds:
            both = inputs.ledger.take(result.source, f"n_for_power_0.8_trials_random.{world}",
                                      f"power 0.8 n, {kind}, {world}, trials random")
            people = inputs.ledger.take(result.source, f"n_for_power_0.8.{world}",
                                        f"power 0.8 n, {kind}, {world}, participants random")
            rows.append((kind, world, shown(both if both is not None else "not reached"),
                         shown(people if people is not None else "not reached")))
    blocks: list = []
    if rows:
        blocks += ["The power simulation (`tomstudy power`: simulated participants of each "
                   "coarse observer on the bank; power of the primary test with participants "
                   "and trials random, beside the participants-only paired t):",
                   Table(("observer", "world", "n for power 0.8, trials random",
                          "n for power 0.8, participants only"), tuple(rows))]
    if missing:
        blocks.append("The power simulation is not available for every coarse observer: run "
                      + ", ".join(missing) + ".")
    return tuple(blocks)


# -- variables


def measured_rows() -> tuple[tuple[str, str, str], ...]:
    """Each measured column with its unit and meaning, as the export's codebook gives them."""
    entries = ((name, column_entry("predictions", name, StudyTerms()))
               for name in MEASURED_COLUMNS)
    return tuple((name, entry.unit or "-", entry.text) for name, entry in entries)


def variables(inputs: Inputs) -> Section:
    """Manipulated and measured variables, the index, and the survey."""
    survey = tuple((q.key, q.kind, q.text) for q in inputs.config.survey)
    return Section("Variables", (
        "**Manipulated** (within participants): the world, and the arm of each main trial "
        "(export column `arm`). The predictor a participant's move is compared with (Ours, the "
        "VAE, and the others above) is not shown to participants: every move is compared "
        "with every predictor's answer at the same start state and step.",
        "**Measured** (export columns, `tomstudy export --what predictions`):",
        Table(("column", "unit", "meaning (the export's codebook)"), measured_rows()),
        "**Index:** alignment error = 1 - cos of the angle between a predictor's move and the "
        "participant's at the same start state and step, in [0, 2] (0: the same direction); a "
        "predictor move shorter than 1e-6 m/s scores 1.",
        "**Survey** (export `survey`), after the trials:",
        Table(("key", "kind", "question"), survey)))


# -- analysis plan


def analysis_plan(inputs: Inputs) -> Section:
    """The primary and secondary tests, alpha, sidedness and the SESOI."""
    alpha = inputs.ledger.take(inputs.stats, "ALPHA", "alpha of every Ours-vs-VAE test")
    sesoi = sesoi_value(inputs)
    a = shown(alpha)
    tests = (
        ("primary: Ours vs the VAE", "per world, the family's err_ours - err_vae per "
         "participant and trial; Clark's min F' (participants and trials random); Ours where "
         "significant and both the by-participant and by-trial effects favour Ours",
         "two-sided", a, "none (each world its own question)", "primary.csv"),
        ("equivalence beside the primary", f"TOST against +-{shown(sesoi)} on the primary "
         "test's SE and df; 95% CI; JZS BF10 (r = 0.707), reported, not deciding",
         "two one-sided", a, "none", "primary.csv"),
        ("secondary: the direct test (H2)", "per world and coarse variant, its error minus "
         "the precise observer's per participant and trial, min F'", "two-sided", a,
         "Holm over the coarse variants", "direct.csv"),
        ("secondary: every predictor", "every pair of predictors per world, paired t and the "
         "crossed mixed model", "two-sided", a, "Holm over the world's pairs",
         "pairwise.csv"),
        ("secondary: per seed pair, per arm", "the paired test per seed pair and for the "
         "family, per arm and pooled", "two-sided", a, "none (counted)",
         "per_seed.csv, by_arm.csv"),
        ("secondary: the paper's test", "paired t-test over participants on the primary seed, "
         "Wilcoxon, d_z, 95% CI", "two-sided (one-sided p reported)", a, "none",
         "summary.json"),
        ("robustness", "crossed mixed model (REML), leave-one-trial-out, human noise ceiling",
         "two-sided", a, "none", "mixed_model.csv, leave_one_trial_out.csv, ceiling.csv"))
    return Section("Analysis plan", (
        f"`tomstudy analyze --study {inputs.study_id}` runs every test below on the kept rows "
        f"(Exclusions). alpha = {a} for every test; the smallest effect of interest (SESOI) of "
        f"the equivalence test is {shown(sesoi)} in alignment error, fixed before any data.",
        Table(("test", "what", "sidedness", "alpha", "correction", "output"), tests)))


def sesoi_value(inputs: Inputs) -> float:
    """The config's smallest effect of interest, cited where it is set (its default otherwise:
    app/core/contracts.py SMALLEST_EFFECT_OF_INTEREST)."""
    if "smallest_effect_of_interest" in inputs.raw_config:
        return inputs.setting("smallest_effect_of_interest", "smallest effect of interest")
    return inputs.ledger.take(inputs.contracts, "SMALLEST_EFFECT_OF_INTEREST",
                              "smallest effect of interest (the config's default)")


# -- exclusions and inference criteria


def exclusions(inputs: Inputs) -> Section:
    """The study config's ExclusionRules in words, and what else never counts."""
    s = inputs.setting
    rules = []
    if s("exclusions.failed_attention_check", "exclude on a failed attention check"):
        rules.append(f"A participant who fails an attention check is excluded. A check passes "
                     f"when at least {s('attention_checks.min_passing_starts', 'passing starts')}"
                     f" of the {inputs.config.start_states} first clicks point within "
                     f"{shown(s('attention_checks.max_angle_deg', 'check angle (deg)'))} "
                     "degrees of the robot's true first move.")
    if s("exclusions.incomplete", "exclude incomplete sessions"):
        rules.append("A participant who did not complete the study is excluded.")
    fast_ms = s("exclusions.too_fast_trial_ms", "too-fast trial (ms)")
    share = s("exclusions.too_fast_max_fraction", "too-fast share")
    rules.append(f"A participant is excluded when more than {shown(share * 100)}% of their "
                 f"scored trials were answered within {shown(fast_ms / 1000)} s of being "
                 "shown; of the participants kept, single trials answered that fast are "
                 "dropped.")
    return Section("Exclusions", (
        Items(tuple(rules)),
        "Never analysed: practice trials and researcher preview (pilot) sessions. Rows that "
        "ran another trial bank (their bank_sha256 is not the bundle's) are counted and left "
        "out of the per-seed and family analyses. A session with "
        f"{s('recruitment.endings.min_failed', 'failed checks for review')} or more failed "
        "checks ends with the review code (Prolific allows no rejection for fewer). Each rule "
        "can be switched off as a sensitivity analysis: `tomstudy analyze --waive RULE`."))


def inference_criteria(inputs: Inputs, roles: dict[str, tuple[str, str]]) -> Section:
    """How a world's result is read, and which worlds count for the hypothesis."""
    alpha = shown(inputs.stats.data.ALPHA)
    exploratory = [w for w, (role, _) in roles.items() if role == "exploratory"]
    counted = [w for w in roles if w not in exploratory]
    return Section("Inference criteria", (
        Items((f"Per world the conclusion is the primary test's: `ours` (significant at "
               f"{alpha}, both factors favour Ours) supports H and the coarse account; `vae` "
               "supports the precise account; else `equivalent` where TOST's p is below "
               f"{alpha} (no difference beyond the SESOI: neither account's predicted "
               "difference); else `inconclusive`.",
               "H2 per world: a coarse variant is `coarse` or `precise` where it differs from "
               f"the precise observer at {alpha} (Holm) with both factors agreeing; the world "
               "is `coarse` if a variant is and none is `precise`, `precise` if every one is, "
               "else `neither`.",
               "Worlds that test H: " + (", ".join(counted) or "none") + ". Exploratory "
               "worlds (" + (", ".join(exploratory) or "none") + ") are reported, never "
               "counted for or against H.")),))


# -- observer family, deviations, sources


def observer_family(inputs: Inputs) -> Section:
    """The simulated observers behind the design goal, every parameter with its source."""
    rows = [(key, shown(inputs.ledger.take(inputs.observers, f"{key}.value", f"observer {key}")),
             source) for key, source in sourced_parameters(inputs.observers.data)]
    hashes = inputs.ledger.take(inputs.manifest, "observers", "coarse observers' content hashes")
    return Section("Observer family", (
        "The design goal and the power simulation rest on one family of simulated observers, "
        "inverse planning (Baker, Saxe & Tenenbaum 2009): each infers the robot's intent from "
        "the segment and the example clips, then moves as that intent does: "
        f"{', '.join(COARSE_VARIANTS)} (coarse: straight, around the scene, with momentum) "
        f"and precise (the world's policy); the goal's observers are {', '.join(GOAL_VARIANTS)}. "
        "Their parameters are the bundle's frozen `configs/observers.yaml`, each fixed from its "
        "source before any comparison with the models; the coarse observers' content hashes "
        f"are {counts(hashes)}.",
        Table(("parameter", "value", "source"), tuple(rows))))


def sourced_parameters(data: dict, prefix: str = "") -> list[tuple[str, str]]:
    """Every {value, source} pair of an observers config, by key path."""
    found = []
    for key, value in data.items():
        path = f"{prefix}{key}"
        if isinstance(value, dict) and {"value", "source"} <= set(value):
            found.append((path, " ".join(str(value["source"]).split())))
        elif isinstance(value, dict):
            found += sourced_parameters(value, f"{path}.")
    return found


def deviations(inputs: Inputs) -> Section:
    """The docs' table of departures from the paper (docs/reproduce/departures.md)."""
    if inputs.departures is None:
        return Section("Deviations from the paper", (
            "docs/reproduce/departures.md is not beside the code, so its table of departures "
            "cannot be shown.",))
    table = readme_table(inputs.departures.data, DEVIATIONS_HEADING)
    inputs.ledger.cite(inputs.departures, f'table under "{DEVIATIONS_HEADING.lstrip("# ")}"',
                       "deviations from the paper", f"{len(table.rows)} rows")
    return Section("Deviations from the paper", (
        "Where this platform departs from the paper (the documentation's table, with why and what "
        "checks each; its rows on worlds and trials are the paper study's). This study's own "
        "worlds, trials and sample are in Design and Sampling plan.", table))


def sources(inputs: Inputs) -> Section:
    """Every number above with its file, key and SHA-256."""
    rows = tuple((c.what, c.value, c.file, c.key, c.sha256) for c in inputs.ledger.citations)
    return Section("Sources", (
        "Every number (or group) in this document, the file and key it was read from, and the "
        "file's SHA-256.", Table(("number", "value", "file", "key", "SHA-256"), rows)))
