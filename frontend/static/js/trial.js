// One trial on its canvas: watch the clips, click the predictions from each start state, submit.
import { ApiError, newUuid } from "./api.js";
import { DraftSaver, clickCount, unsavedText } from "./drafts.js";
import { $, confirmNotice, show } from "./page.js";
import { ClipPlayer, trialClips } from "./player.js";
import { PredictionInput } from "./predict.js";
import { say } from "./words.js";

/** A short break screen between two trials of the same part; resolves on Continue. */
export function showPause(done, next) {
  const what = done.is_practice ? `Practice trial ${done.number} of ${done.of}` : `Trial ${done.number} of ${done.of}`;
  $("pause-heading").textContent = `Part ${done.part} of ${done.parts} · ${what} saved`;
  const button = $("pause-done");
  button.textContent = next.is_practice ? "Continue to the next practice trial" : `Continue to trial ${next.number}`;
  show("pause");
  button.focus();
  return new Promise((resolve) => { button.onclick = resolve; });
}

/**
 * One practice or main trial: watch the clips, then predict from each start state. Every
 * change is saved as a draft, so a reload (or a new tab that takes over) resumes at the
 * same start state with the same clicks, without the clips again.
 */
export class TrialScreen {
  constructor(state, app) {
    this.trial = state.step;
    this.app = app;
    this.api = app.api;
    this.telemetry = app.telemetry;
    this.draft = this.trial.draft;
    this.replays = this.draft?.replays ?? 0;
    this.canvas = $("trial-canvas");
    this.player = new ClipPlayer(this.canvas, this.trial.scene, trialClips(this.trial), {
      onCaption: (text) => { $("trial-caption").textContent = text; },
    });
    this.input = null;
    this.saver = new DraftSaver(this.api, this.draft?.seq ?? 0, this.draft ? clickCount(this.draft) : 0, {
      onStatus: (text, kind) => this.setSaveStatus(text, kind),
      onRefused: (error, lost) => this.refused(error, unsavedText(lost)),
    });
    const { part, parts, number, of } = this.trial;
    const which = this.trial.is_practice ? `Practice trial ${number} of ${of} (not counted)` : `Trial ${number} of ${of}`;
    $("trial-heading").textContent = `Part ${part} of ${parts} · ${which}`;
    this.setSaveStatus("");
  }

  run() {
    addEventListener("beforeunload", askBeforeLeaving);
    return new Promise((resolve, reject) => {
      this.resolve = resolve;
      this.reject = reject;
      $("replay").onclick = () => this.replay();
      $("start-predicting").onclick = () => this.predict();
      $("undo").onclick = () => this.input?.undo();
      $("reset").onclick = () => this.input?.reset();
      $("next").onclick = () => this.confirm();
      if (this.draft) this.resume();
      else this.watch();
    });
  }

  /** Back after a reload or a takeover: straight to the predictions, clicks restored. */
  resume() {
    this.predict(this.draft);
    const clicks = this.input.clickCount();
    this.setMessage(clicks
      ? `Welcome back: your ${clicks} click${clicks === 1 ? "" : "s"} so far ${clicks === 1 ? "is" : "are"} restored.`
      : "Welcome back: continue with your predictions.");
  }

  /** Stop drawing and saving (the trial is stored, or the session went to another tab). */
  stop() {
    removeEventListener("beforeunload", askBeforeLeaving);
    this.saver.stop();
    this.input?.destroy();
    this.player.stop();
  }

  setMessage(text, kind = "ok") {
    const message = $("trial-message");
    message.textContent = text;
    message.className = `message one-line ${kind}`;
  }

  setSaveStatus(text, kind = "ok") {
    const status = $("save-status");
    status.textContent = text;
    status.className = `save-status ${kind}`;
  }

  /** Play the clips: the first time to the end; a replay (`again`) can be left at any time. */
  async watch(again = false) {
    this.input?.pause();
    $("predict-controls").hidden = true;
    $("legend-predict").hidden = true;
    $("trial-side").hidden = true;
    $("replay").disabled = true;
    const leave = $("start-predicting");
    leave.disabled = !again;
    leave.hidden = false;
    if (again) leave.textContent = this.input ? "Stop and go back to predictions" : "Stop and make predictions";
    this.setMessage(again
      ? "Watching the clips again. You can stop at any time with the button."
      : "Watch the clips closely.");
    const finished = await this.player.play();
    if (!finished) return;
    this.telemetry.log("clip_finished", { trial_id: this.trial.trial_id, replays: this.replays });
    $("trial-caption").textContent = "The clips are over.";
    $("replay").disabled = false;
    $("start-predicting").disabled = false;
    $("start-predicting").textContent = this.input ? "Back to predictions" : "Make predictions";
    this.setMessage("Press the button to make your predictions, or watch the clips again.");
    $("start-predicting").focus();
  }

  replay() {
    this.replays += 1;
    this.telemetry.log("replay", { trial_id: this.trial.trial_id, replays: this.replays });
    if (this.input) this.saveDraft();
    this.watch(true);
  }

  predict(draft = null) {
    this.player.stop();
    $("start-predicting").hidden = true;
    $("start-predicting").disabled = true;
    $("predict-controls").hidden = false;
    $("legend-predict").hidden = false;
    $("trial-side").hidden = false;
    $("replay").disabled = false;
    if (!this.input) {
      this.input = new PredictionInput(this.canvas, this.trial, {
        rules: this.app.rules.predictions,
        onChange: (input, options) => this.changed(input, options),
        onMessage: (text, kind) => this.setMessage(text, kind),
        overview: $("overview-canvas"),
      });
      if (draft) this.input.restore(draft);
    }
    this.input.start();
    this.changed(this.input);
    this.setMessage(say("predict_prompt", { steps: this.trial.steps_to_predict }));
    this.canvas.focus({ preventScroll: true });
  }

  saveDraft() {
    if (this.submitting) return;
    this.saver.save({ trial_id: this.trial.trial_id, replays: this.replays, ...this.input.snapshot() });
  }

  changed(input, { confirm = false } = {}) {
    const next = $("next");
    const states = this.trial.start_states.length;
    next.disabled = !input.stateDone();
    next.textContent = input.isLast() ? "Submit predictions" : `Next start position (${input.index + 2} of ${states})`;
    $("trial-caption").textContent = `Start position ${input.index + 1} of ${states}: `
      + `${input.current.length} of ${this.trial.steps_to_predict} positions placed.`;
    this.saveDraft();
    if (confirm) this.confirm();
  }

  confirm() {
    if (!this.input?.stateDone()) return;
    if (!this.input.isLast()) {
      this.input.next();
      this.canvas.focus({ preventScroll: true });
      return;
    }
    this.submit();
  }

  async submit() {
    if (!this.input.allDone() || this.submitting) return;
    this.submitting = true;
    this.saver.stop(); // the submission carries every click; a late draft would only be refused
    $("next").disabled = true;
    $("replay").disabled = true;
    this.body ??= { submission_id: newUuid(), ...this.input.body(this.replays), reduced_motion: this.player.reducedMotion };
    this.setMessage("Saving your predictions…");
    try {
      const state = await this.api.predictions(this.body, {
        onRetry: () => this.setMessage("Connection problem: retrying to save your predictions…", "error"),
      });
      this.stop();
      this.setMessage("");
      if (this.trial.feedback) await this.showFeedback();
      this.resolve(state);
    } catch (error) {
      this.submitting = false;
      if (error instanceof ApiError && error.status < 500) this.refused(error, "These predictions were not saved.");
      else this.reject(error);
    }
  }

  /**
   * After a practice trial (whose payload alone says where the robot goes): each start
   * position with the person's clicks beside the robot's moves; resolves on Continue.
   */
  showFeedback() {
    const states = this.trial.start_states.length;
    const next = $("next");
    $("undo").hidden = true;
    $("reset").hidden = true;
    $("feedback-legend").hidden = false;
    $("legend-predict").hidden = true;
    return new Promise((resolve) => {
      const showAt = (index) => {
        this.input.review(this.trial.feedback.robot, index);
        $("trial-caption").textContent = `Practice feedback, start position ${index + 1} of ${states}`;
        this.setMessage(say("practice_feedback"));
        const last = index === states - 1;
        next.textContent = last ? "Continue" : `Next start position (${index + 2} of ${states})`;
        next.disabled = false;
        next.onclick = () => (last ? done() : showAt(index + 1));
        next.focus();
      };
      const done = () => {
        $("undo").hidden = false;
        $("reset").hidden = false;
        $("feedback-legend").hidden = true;
        resolve();
      };
      showAt(0);
    });
  }

  /**
   * The server refused this trial's clicks (a 4xx no retry changes): never move on silently.
   * Another tab holds the session: say so and offer to continue here. Otherwise the trial
   * was answered elsewhere: say that these clicks were not used, and go on when the person
   * has read it.
   */
  async refused(error, what) {
    this.stop();
    if (error.otherTab) {
      this.app.tabLost(error.notice, what && `${what} The study had moved to the other tab.`);
      return;
    }
    if (error.status !== 404 && error.status !== 409) {
      this.reject(error);
      return;
    }
    console.warn(error.detail); // the field name, for whoever reads the console; not the person
    await confirmNotice({
      title: "This trial was already answered",
      text: `${what ? `${what} ` : ""}This trial had already been answered, in another tab or window, `
        + "and that answer is kept. The study continues with the next step.",
    });
    this.resolve(null);
  }
}

/** Leaving mid-trial asks first (the browser's own question; clicks are saved as drafts too). */
function askBeforeLeaving(event) {
  event.preventDefault();
  event.returnValue = "";
}
