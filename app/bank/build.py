"""`tomstudy build-trials`: held-out trajectories -> the study's trial bank (JSON + meta.json).

Per world: the test split every checkpoint held out (all seeds share the split); segments cut
where the world says the robot's behaviour is still visible (`World.visible_ends`: before a
Highway lane change completes, well before an Obstacle goal is reached); main trials kept by
the config's `main_trial_selection` in two arms (the first usable ones; and of further ones,
those the rule ranks first, robot labels taking turns: where the Ours and VAE families disagree
most, or where the observer hypotheses differ most); `start_states` start states on the data
near the robot; every seed of both models, a constant-velocity baseline and the world's own
policy (`World.robot_policy_actions`, its expected move: the mean of POLICY_ROLLOUTS runs; where
the world's starts are recorded states, `World.starts_as_recorded`, what the robot recorded at
each did next) answered for every start state, and every plug-in predictor the config names
(app/predictors/), each a family of one answer. Everything is computed from the rounded numbers
the participant is shown. Nothing here depends on which world it is.
Start states are chosen by start_states.py; attention checks by attention.py.
"""

import platform
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

import app
from app.bank.attention import choose_checks
from app.bank.start_states import (
    NoStartStates,
    clickable_ends,
    clickable_states,
    covered_states,
    start_states,
)
from app.core.alignment import alignment_error
from app.core.files import sha256_file, write_json
from app.data.trajectory import HUMAN, ROBOT, Covered, TrajectorySet
from app.layout import Layout
from app.observers.config import default_observers
from app.observers.predictor import observer_predictors
from app.predictors.builtin import CheckpointPredictor, ConstantVelocity
from app.predictors.protocol import Predictor, ask
from app.predictors.registry import load_predictor
from app.study.config import StudyConfig
from app.study.trial_payload import predictor_inputs
from app.study.trials import (
    HEADING_DECIMALS,
    NO_SEED,
    POS_DECIMALS,
    SIZE_DECIMALS,
    BankFile,
    Clip,
    ModelAnswer,
    TrialRecord,
    WorldBank,
    clip_sha256,
)
from app.worlds.registry import World, build_world

STEP_PERCENTILE = 99.5
EXTRA_CANDIDATES = 40  # segments tried as attention checks (app/bank/attention.py)
POLICY_ROLLOUTS = 8  # runs of the world's policy averaged into its expected move


@dataclass
class WorldInputs:
    """What one world's bank is built from."""

    world: World
    trajs: TrajectorySet
    models: dict[str, list]  # model name -> one TrainedModel per seed, the primary first
    held_out: np.ndarray
    trajectories_path: Path
    covered: Covered  # robot states start states are drawn from
    covered_trajectories: int
    seeds: list[int]  # the model family's seeds, in the order of every models list
    data_dir: Path  # meta.json names the inputs relative to it
    plugins: list[Predictor] = field(default_factory=list)  # the config's `predictors`


def build_trials(config: StudyConfig, study_id: str, layout: Layout) -> Path:
    """Build the study's bank.json and its meta.json; returns the bank path."""
    started = time.perf_counter()
    worlds, meta_worlds = {}, {}
    for w_index, name in enumerate(config.worlds):
        inputs = load_inputs(config, name, layout)
        rng = np.random.default_rng(np.random.SeedSequence([config.bank_seed, w_index]))
        worlds[name], meta_worlds[name] = build_world_bank(config, inputs, rng)
    bank = BankFile(study_id=study_id, steps_to_predict=config.steps_to_predict, worlds=worlds)
    bank_path = layout.bank(study_id)
    write_json(bank_path, bank.model_dump())
    write_json(layout.bank_meta(study_id), {
        "study_id": study_id, "config": config.model_dump(mode="json"), "worlds": meta_worlds,
        "bank_sha256": sha256_file(bank_path), "package_version": app.__version__,
        "python": platform.python_version(), "numpy": np.__version__,
        "wall_time_s": round(time.perf_counter() - started, 2),
    })
    return bank_path


def load_inputs(config: StudyConfig, name: str, layout: Layout) -> WorldInputs:
    """The world, its trajectories, every seed's checkpoints and the test split they share."""
    from app.core.files import trajectory_hash
    from app.learning.checkpoint import CheckpointError, check_matches_data, load_model

    npz_path = layout.trajectories(name)
    if not npz_path.is_file():
        raise FileNotFoundError(f"{npz_path}: no trajectories; run `tomstudy simulate {name}`")
    trajs = TrajectorySet.load(npz_path)
    data_hash = trajectory_hash(trajs)
    models, splits = {"ours": [], "vae": []}, []  # test trajectory sets
    for kind, seed in ((k, s) for k in models for s in config.models.seeds):
        path = layout.checkpoint(name, kind, seed)
        model = load_model(path, world=name)
        check_matches_data(model, name, trajs.dt_s, data_hash)
        if model.n_actions != config.steps_to_predict:
            raise CheckpointError(f"{path}: predicts {model.n_actions} steps, the study asks "
                                  f"for {config.steps_to_predict}")
        models[kind].append(model)
        splits.append(set(model.data_meta["split_trajectories"]["test"]))
    held_out = np.array(sorted(set.intersection(*splits)), dtype=np.int64)
    learned = np.setdiff1d(np.arange(len(trajs)), sorted(set.union(*splits)))
    world = build_world(name)
    world.prepare(layout)  # e.g. a recorded world indexes its recordings' futures
    return WorldInputs(world, trajs, models, held_out, npz_path,
                       covered_states(trajs, learned, config.steps_to_predict), len(learned),
                       list(config.models.seeds),
                       layout.root, [load_predictor(p) for p in config.predictors])


def build_world_bank(config: StudyConfig, inputs: WorldInputs,
                     rng: np.random.Generator) -> tuple[WorldBank, dict]:
    """One world's trials: main pool, practice and attention checks."""
    trajs, world = inputs.trajs, inputs.world
    label_name = world.robot_label
    max_step = config.prediction_input.max_step_factor * robot_step_percentile(
        trajs, inputs.held_out)
    min_step = min_click(config, max_step)
    dropped = {}
    if world.starts_as_recorded:
        covered, dropped = clickable_states(inputs.covered, min_step, trajs.dt_s)
        inputs = replace(inputs, covered=covered)
    candidates, dropped_ends = segment_candidates(config, world, trajs, inputs.held_out,
                                                  model_history(inputs), rng, min_step)
    selection = config.main_trial_selection
    arms = selection.arm_sizes(config.bank_trials_per_world)
    rule_arm = sum(size for arm, size in arms.items() if arm != "random")
    pool_size = arms["random"] + rule_arm * selection.candidates_per_trial
    needed = pool_size + config.practice_trials + config.attention_checks.per_world
    if len(candidates) < needed:
        raise ValueError(f"{world.name}: only {len(candidates)} held-out trajectories give a "
                         f"usable segment, the bank needs {needed}; simulate more")
    scene = trajs.scene.model_dump()
    practice, used = regular_trials(config, inputs, candidates, config.practice_trials,
                                    max_step, scene, rng)
    pool, tried = regular_trials(config, inputs, candidates[used:], pool_size, max_step, scene,
                                 rng)
    scores = arm_scores(config, inputs, pool[arms["random"]:], max_step, scene)
    main = main_trials(pool, arms, scores)
    used += tried
    checks, attention = attention_trials(config, inputs, candidates[used:], main, max_step,
                                         scene, rng)
    built = practice + main + checks
    kinds = (["practice"] * len(practice) + ["main"] * len(main)
             + ["attention"] * len(checks))
    trials = [t.model_copy(update={"kind": kind, "trial_id": f"{world.name}-{kind}-{i:03d}"})
              for kind in ("main", "practice", "attention")
              for i, t in enumerate(t for t, k in zip(built, kinds, strict=True) if k == kind)]
    bank = WorldBank(world=world.name, dt_s=trajs.dt_s, scene=scene,
                     robot_label_name=label_name, label_names=trajs.label_names[label_name],
                     max_step_m=round(max_step, 4), min_step_m=min_step, trials=trials)
    bank = with_code_answers(bank, config.steps_to_predict,
                             [*observer_predictors(default_observers()), *inputs.plugins])
    meta = world_meta(inputs, trials, attention)
    meta["segments_skipped_no_data_starts"] = used - len(practice) - len(pool)
    if world.starts_as_recorded:
        meta["start_candidates_dropped"] = dropped | {"segment_ends_short_moves": dropped_ends}
    meta["main_trial_selection"] = selection_meta(selection, arms, pool, main, scores)
    return bank, meta


def min_click(config: StudyConfig, max_step: float) -> float:
    """The shortest click the study accepts (m): the bank's `min_step_m`."""
    return round(config.prediction_input.min_step_fraction * max_step, 4)


def model_history(inputs: WorldInputs) -> int:
    """Steps every model reads before a segment's end (the longest segment_len of them)."""
    return max(m.segment_len for family in inputs.models.values() for m in family)


def model_disagreement(trial: TrialRecord) -> float:
    """Mean 1-cos between every Ours seed's and every VAE seed's answers, over the trial's start
    states and steps: how far apart the two families are, not two checkpoints."""
    return float(np.mean([alignment_error(np.asarray(ours.actions),
                                          np.asarray(vae.actions)).mean()
                          for ours in trial.predictions["ours"]
                          for vae in trial.predictions["vae"]]))


def arm_scores(config: StudyConfig, inputs: WorldInputs, candidates: list[TrialRecord],
               max_step: float, scene: dict) -> list[float]:
    """How strongly the selection rule wants each candidate of its arm (higher first)."""
    rule = config.main_trial_selection
    if rule.rule != "discriminability":
        return [model_disagreement(t) for t in candidates]
    from app.observers.config import default_observers
    from app.observers.family import answers_of, discriminability
    from app.prediction_view import view_click_sd_deg

    observers = default_observers()  # the configs dir's, frozen into the bundle beside it
    world = provisional_world(inputs, candidates, max_step, scene, config)
    view_sd = view_click_sd_deg(world, observers.click_sd_px.value)
    answers = answers_of(world, world.trials, config.steps_to_predict, observers, view_sd)
    chosen_on = np.array([inputs.seeds.index(s) for s in rule.selection_seeds])
    return [float(v) for v in discriminability(answers, chosen_on)]


def provisional_world(inputs: WorldInputs, candidates: list[TrialRecord], max_step: float,
                      scene: dict, config: StudyConfig) -> WorldBank:
    """The world's bank as it would be with `candidates` as its main trials (for scoring)."""
    return WorldBank(world=inputs.world.name, dt_s=inputs.trajs.dt_s, scene=scene,
                     robot_label_name=inputs.world.robot_label,
                     label_names=inputs.trajs.label_names[inputs.world.robot_label],
                     max_step_m=round(max_step, 4), min_step_m=min_click(config, max_step),
                     trials=[t.model_copy(update={"kind": "main"}) for t in candidates])


def main_trials(pool: list[TrialRecord], arms: dict[str, int],
                scores: list[float]) -> list[TrialRecord]:
    """The random arm (the pool's first trials), then the rule's arm: of the rest (scored by
    `scores`), per robot label the highest scored, robot labels taking turns."""
    random_arm, rest = pool[: arms["random"]], pool[arms["random"]:]
    rule_arm = next((arm for arm in arms if arm != "random"), None)
    by_label: dict[int, list[tuple[float, TrialRecord]]] = {}
    for score, trial in zip(scores, rest, strict=True):
        by_label.setdefault(trial.robot_label, []).append((score, trial))
    ranked = {label: [t for _, t in sorted(trials, key=lambda st: st[0], reverse=True)]
              for label, trials in by_label.items()}
    chosen = interleave(ranked)[: arms.get(rule_arm, 0)]
    return ([t.model_copy(update={"arm": "random"}) for t in random_arm]
            + [t.model_copy(update={"arm": rule_arm}) for t in chosen])


def selection_meta(selection, arms: dict[str, int], pool: list[TrialRecord],
                   main: list[TrialRecord], scores: list[float]) -> dict:
    """meta.json's account of the main-trial selection: the arms, the mean family disagreement
    of each arm and of the candidates the rule's arm was chosen from, and the rule's scores
    (of the candidates and of those it kept) with the seeds it read."""
    def mean_disagreement(trials: list[TrialRecord]) -> float | None:
        return round(float(np.mean([model_disagreement(t) for t in trials])), 4) if trials \
            else None

    candidates = pool[arms["random"]:]
    kept = {(t.source_index, t.segment_start) for t in main if t.arm != "random"}
    chosen = [s for s, t in zip(scores, candidates, strict=True)
              if (t.source_index, t.segment_start) in kept]
    return {"rule": selection.rule, "arms": arms, "candidates": len(candidates),
            "ours_vs_vae_candidates": mean_disagreement(candidates),
            **{f"ours_vs_vae_{arm}": mean_disagreement([t for t in main if t.arm == arm])
               for arm in arms},
            "selection_seeds": selection.selection_seeds or "every seed",
            "score_candidates": round(float(np.mean(scores)), 4) if scores else None,
            "score_kept": round(float(np.mean(chosen)), 4) if chosen else None}


def regular_trials(config: StudyConfig, inputs: WorldInputs, candidates: list, count: int,
                   max_step: float, scene: dict, rng: np.random.Generator
                   ) -> tuple[list[TrialRecord], int]:
    """The first `count` candidates that have data-covered start states; and how many were tried."""
    built, tried = [], 0
    progress = tqdm(total=count, desc=f"build-trials {inputs.world.name}", unit="trial")
    for src, start, end in candidates:
        if len(built) == count:
            break
        tried += 1
        try:
            built.append(make_trial(config, inputs, src, start, end, max_step, scene, rng))
        except NoStartStates:
            continue
        progress.update(1)
    progress.close()
    if len(built) < count:
        raise ValueError(f"{inputs.world.name}: only {len(built)} segments have "
                         f"{config.start_states} start states on the data, the bank needs "
                         f"{count}; simulate more")
    return built, tried


def world_meta(inputs: WorldInputs, trials: list[TrialRecord], attention: dict) -> dict:
    """Input hashes and counts for meta.json."""
    labels = [t.robot_label for t in trials if t.kind == "main"]
    starts = [s.start_kind for t in trials if t.kind == "main" for s in t.start_states]
    def relative(path: Path) -> str:
        return Path(path).relative_to(inputs.data_dir).as_posix()

    return {
        "trajectories": relative(inputs.trajectories_path),
        "trajectories_sha256": sha256_file(inputs.trajectories_path),
        "held_out_trajectories": len(inputs.held_out),
        "checkpoints": {f"{kind}/seed{seed}": {"path": relative(m.path),
                                               "content_hash": m.content_hash,
                                               "file_sha256": sha256_file(m.path)}
                        for kind, family in inputs.models.items()
                        for seed, m in zip(inputs.seeds, family, strict=True)},
        "trials": {kind: sum(t.kind == kind for t in trials)
                   for kind in ("main", "practice", "attention")},
        "main_robot_labels": {str(v): labels.count(v) for v in sorted(set(labels))},
        "attention_checks": attention,
        "start_states_from": {"trajectories": inputs.covered_trajectories,
                              "robot_states": len(inputs.covered)},
        "main_start_kinds": {k: starts.count(k) for k in sorted(set(starts))},
    }


def robot_step_percentile(trajs: TrajectorySet, index: np.ndarray) -> float:
    """A high percentile of the robot's step length over the valid steps of `index`."""
    steps = []
    for i in index:
        track = trajs.positions[i, : trajs.lengths[i] + 1, ROBOT]
        steps.append(np.linalg.norm(np.diff(track, axis=0), axis=1))
    return float(np.percentile(np.concatenate(steps), STEP_PERCENTILE))


# ---------------------------------------------------------------- segments

def segment_candidates(config: StudyConfig, world: World, trajs: TrajectorySet,
                       held_out: np.ndarray, need_segment: int, rng: np.random.Generator,
                       min_step: float) -> tuple[list[tuple[int, int, int]], int]:
    """(trajectory, segment start, segment end) per usable trajectory, labels interleaved;
    and how many ends were dropped because a recorded next move is shorter than `min_step`
    (only where the world's starts are recorded states: start_states.py)."""
    by_label: dict[int, list] = {}
    dropped = 0
    for i in rng.permutation(held_out):
        length = int(rng.integers(config.segment_steps.min, config.segment_steps.max + 1))
        ends = segment_ends(world, trajs, int(i), max(length, need_segment),
                            config.steps_to_predict)
        if world.starts_as_recorded:
            clickable = clickable_ends(trajs, int(i), ends, config.steps_to_predict, min_step)
            dropped += len(ends) - len(clickable)
            ends = clickable
        if len(ends):
            end = int(rng.choice(ends))
            by_label.setdefault(int(trajs.labels[world.robot_label][i]), []).append(
                (int(i), end - length, end))
    return interleave(by_label), dropped


def interleave(groups: dict[int, list]) -> list:
    """Round-robin over groups, so any prefix covers the labels evenly."""
    out, queues = [], [list(v) for _, v in sorted(groups.items())]
    while any(queues):
        for queue in queues:
            if queue:
                out.append(queue.pop(0))
    return out


def segment_ends(world: World, trajs: TrajectorySet, i: int, history: int,
                 n_after: int) -> np.ndarray:
    """End steps of trajectory i with `history` steps before and `n_after` after, where the
    world shows the robot's behaviour under way but not finished."""
    length = int(trajs.lengths[i])
    ends = np.arange(history, length - n_after + 1)
    if not len(ends):
        return ends
    return world.visible_ends(trajs.positions[i, : length + 1, ROBOT].astype(np.float64), ends)


# ---------------------------------------------------------------- one trial

def make_trial(config: StudyConfig, inputs: WorldInputs, src: int, start: int, end: int,
               max_step: float, scene: dict, rng: np.random.Generator) -> TrialRecord:
    """Examples, segment, start states and every predictor's answers for one segment."""
    trajs = inputs.trajs
    label_name = inputs.world.robot_label
    shown = clip_of(trajs, src, start, end, label_name)
    model_input = clip_of(trajs, src, end - model_history(inputs), end, label_name).positions
    segment = np.asarray(shown.positions)
    starts = start_states(inputs.world, inputs.trajs, inputs.covered, (src, end), segment,
                          config.start_states, config.steps_to_predict, max_step, rng)
    states = starts.states
    examples = [clip_of(trajs, e, 0, int(trajs.lengths[e]), label_name)
                for e in pick_examples(trajs, inputs.held_out, src, label_name,
                                       config.examples_per_trial, rng)]
    joint = np.array([[s.robot, s.human] for s in states])
    dt, n = trajs.dt_s, config.steps_to_predict
    asked = (model_input, joint, [s.robot_heading for s in states], dt, n)
    predictions = {kind: [stored_answer(CheckpointPredictor(model), seed, *asked)
                          for seed, model in zip(inputs.seeds, family, strict=True)]
                   for kind, family in inputs.models.items()}
    labels = {k: int(v[src]) for k, v in trajs.labels.items()}
    human_v = (segment[-1, HUMAN] - segment[-2, HUMAN]) / dt
    policy = starts.recorded_moves if starts.recorded_moves is not None else [
        expected_policy(inputs.world, s, human_v, labels, config.steps_to_predict, rng)
        for s in states]
    record = TrialRecord(
        trial_id="", world=inputs.world.name, kind="", source_index=src, segment_start=start,
        robot_label=labels[label_name], examples=examples, segment=shown, start_states=states,
        model_input=model_input, predictions=predictions,
        cv_actions=np.round(ask(ConstantVelocity(), *asked).actions, 5).tolist(),
        policy_actions=np.round(np.asarray(policy), 5).tolist(), clip_sha256="")
    return record.model_copy(update={"clip_sha256": clip_sha256(
        scene, dt, record.browser_payload())})


def expected_policy(world: World, state, human_v: np.ndarray, labels: dict, n_steps: int,
                    rng: np.random.Generator) -> np.ndarray:
    """The robot policy's expected actions [n, 2] from a start state: the mean of
    POLICY_ROLLOUTS runs of a stochastic policy (the precise observer's answer and every check's
    truth: one run's sampling noise moves steps 2-3 by 4-6 degrees)."""
    runs = [world.robot_policy_actions(np.asarray([state.robot, state.human]),
                                       state.robot_heading, state.robot_speed, human_v, labels,
                                       n_steps, rng) for _ in range(POLICY_ROLLOUTS)]
    return np.mean(runs, axis=0)


def with_code_answers(world: WorldBank, n_steps: int,
                      predictors: list[Predictor]) -> WorldBank:
    """The world's bank with every trial answered by each code predictor (the coarse observers,
    then the config's plug-ins), asked with the trial as its participants are shown it."""
    trials = []
    for trial in world.trials:
        asked = predictor_inputs(world, n_steps, trial)
        answers = {p.name: [stored_answer(p, NO_SEED, *asked)] for p in predictors}
        trials.append(trial.model_copy(update={"predictions": trial.predictions | answers}))
    return world.model_copy(update={"trials": trials})


def stored_answer(predictor: Predictor, seed: int, model_input: list, joint: np.ndarray,
                  headings: list[float], dt_s: float, n_steps: int,
                  shown: dict | None = None) -> ModelAnswer:
    """One predictor's answer to a trial: its latent, code and actions from every start state
    (rounded as stored; app/bank/model_answers.py recomputes them at start-up)."""
    answer = ask(predictor, model_input, joint, headings, dt_s, n_steps, shown)
    return ModelAnswer(seed=seed, z=answer.z, code=answer.code,
                       actions=np.round(answer.actions, 5).tolist(),
                       content_hash=predictor.content_hash)


def clip_of(trajs: TrajectorySet, i: int, start: int, end: int, label_name: str) -> Clip:
    """Steps start..end of trajectory i, rounded as shown."""
    return Clip(
        positions=np.round(trajs.positions[i, start:end + 1], POS_DECIMALS).tolist(),
        headings=np.round(trajs.headings[i, start:end + 1], HEADING_DECIMALS).tolist(),
        robot_label=int(trajs.labels[label_name][i]), source_index=i,
        sizes=None if trajs.sizes is None else clip_sizes(trajs.sizes[i]))


def clip_sizes(sizes: np.ndarray) -> list[list[float]]:
    """Both agents' (length, width) [2, 2] m as a clip stores them: 4.09, not float32's
    4.090000152587891."""
    return np.round(sizes.astype(np.float64), SIZE_DECIMALS).tolist()


def pick_examples(trajs: TrajectorySet, held_out: np.ndarray, src: int, label_name: str,
                  count: int, rng: np.random.Generator) -> list[int]:
    """`count` other held-out trajectories, covering as many robot labels as possible."""
    groups: dict[int, list] = {}
    for i in rng.permutation(held_out[held_out != src]):
        groups.setdefault(int(trajs.labels[label_name][i]), []).append(int(i))
    order = list(groups)
    rng.shuffle(order)
    return interleave({k: groups[key] for k, key in enumerate(order)})[:count]


# ---------------------------------------------------------------- kinds

def attention_trials(config: StudyConfig, inputs: WorldInputs, candidates: list,
                     main: list[TrialRecord], max_step: float, scene: dict,
                     rng: np.random.Generator) -> tuple[list[TrialRecord], dict]:
    """Of up to EXTRA_CANDIDATES segments, the checks app/bank/attention.py keeps: failed by
    going straight on, passed by every attentive observer (or else the fairest).

    Their start states come from the same rule and the same data as main trials', so
    nothing the browser gets (where the starts lie, how far apart) tells a check from a
    main trial.
    """
    rule = config.attention_checks
    pool = []
    for src, start, end in tqdm(candidates[:EXTRA_CANDIDATES],
                                desc=f"attention candidates {inputs.world.name}", unit="trial"):
        try:
            pool.append(make_trial(config, inputs, src, start, end, max_step, scene, rng))
        except NoStartStates:
            continue
    if len(pool) < rule.per_world:
        raise ValueError(f"{inputs.world.name}: not enough segments left for "
                         f"{rule.per_world} attention check(s); simulate more")
    chosen, meta = choose_checks(
        provisional_world(inputs, pool, max_step, scene, config),
        provisional_world(inputs, main, max_step, scene, config), config.steps_to_predict,
        rule, default_observers())
    return [pool[i] for i in chosen], meta
