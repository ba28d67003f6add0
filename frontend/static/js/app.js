// The participant app: one page driven by GET /api/sessions/{token}/state.
import { ApiError, StudyApi, newUuid } from "./api.js";
import { InstructionsDemo } from "./demo.js";
import { ClipPlayer, trialClips } from "./player.js";
import { PredictionInput } from "./predict.js";

const MIN_WIDTH_PX = 900;
const MIN_HEIGHT_PX = 600;
const RECRUITMENT_PARAMS = ["PROLIFIC_PID", "STUDY_ID", "SESSION_ID", "workerId", "assignmentId", "hitId", "turkSubmitTo"];
const REDIRECT_DELAY_MS = 5000;
const SCREENS = ["loading", "unsupported", "consent", "instructions", "trial", "survey", "done", "error"];

const $ = (id) => document.getElementById(id);

/**
 * One handler per phase the server sends (app/study/plan.py `Phase`; the page lists them in
 * `data-phases`). `show` resolves with the next state once the participant's answer is
 * stored (or with null: read the state again); `ends` marks the phase that ends the session.
 */
const PHASE_HANDLERS = {
  consent: { show: (app, state) => app.showConsent(state.step) },
  instructions: { show: (app, state) => app.showInstructions(state.step) },
  practice: { show: (app, state) => app.showTrial(state) },
  trial: { show: (app, state) => app.showTrial(state) },
  survey: { show: (app, state) => app.showSurvey(state.step) },
  done: { show: (app, state) => app.showDone(state), ends: true },
};

/** The handler of every phase the page lists; throws on a phase this script cannot show. */
function handlerTable(phases) {
  const missing = phases.filter((phase) => !Object.hasOwn(PHASE_HANDLERS, phase));
  if (missing.length) throw new Error(`no handler for phase ${missing.join(", ")}`);
  return new Map(phases.map((phase) => [phase, PHASE_HANDLERS[phase]]));
}

function show(screen) {
  for (const name of SCREENS) $(`screen-${name}`).hidden = name !== screen;
}

/** Why this device cannot run the study ({code, text}: code as POST /screen-out takes it), or null. */
function unsupportedReason() {
  const touchOnly = matchMedia("(any-pointer: coarse)").matches && !matchMedia("(any-pointer: fine)").matches;
  if (touchOnly) {
    return { code: "touch_only", text: "This study needs a mouse or touchpad: touch-only devices are not supported." };
  }
  if (innerWidth < MIN_WIDTH_PX || innerHeight < MIN_HEIGHT_PX) {
    return {
      code: "window_too_small",
      text: `Your browser window is ${innerWidth} × ${innerHeight} pixels; the study needs at least ${MIN_WIDTH_PX} × ${MIN_HEIGHT_PX}.`,
    };
  }
  return null;
}

/** Batches telemetry events and posts them; kept in memory until the server takes them. */
class Telemetry {
  constructor(api) {
    this.api = api;
    this.queue = [];
    this.timer = null;
  }

  log(kind, data = {}) {
    this.queue.push({ submission_id: newUuid(), kind, t_client_ms: Date.now(), data });
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.flush(), 1000);
  }

  async flush({ keepalive = false } = {}) {
    if (!this.api.token || !this.queue.length) return;
    const batch = this.queue.splice(0, 100);
    try {
      const response = await this.api.events(batch, { keepalive });
      if (response.status >= 500) this.queue.unshift(...batch);
    } catch {
      this.queue.unshift(...batch); // offline: try again with the next event
    }
  }
}

function recruitmentFromUrl() {
  const params = new URLSearchParams(location.search);
  const recruitment = {};
  for (const key of RECRUITMENT_PARAMS) if (params.get(key)) recruitment[key] = params.get(key);
  return recruitment;
}

/** The researcher preview key of a lab member's test link, or null. */
function previewFromUrl() {
  return new URLSearchParams(location.search).get("preview");
}

/** A server refusal's message for a person: `field: message` without the field. */
function forPeople(detail) {
  return String(detail).replace(/^[\w.-]+: /, "");
}

function clientInfo() {
  return {
    screen_w: innerWidth,
    screen_h: innerHeight,
    touch_only: false,
    user_agent: navigator.userAgent,
  };
}

class ParticipantApp {
  constructor(root) {
    const studyId = root.dataset.studyId;
    this.api = new StudyApi(studyId);
    this.telemetry = new Telemetry(this.api);
    this.storageKey = `tomstudy.${studyId}.session`;
    this.phases = JSON.parse(root.dataset.phases);
    this.screenOutPhases = JSON.parse(root.dataset.screenOutPhases);
  }

  async run() {
    show("loading");
    this.handlers = handlerTable(this.phases);
    const started = await this.ensureSession();
    if (!started) return;
    this.watchPage();
    let state = await this.api.state();
    if (!this.handler(state.phase).ends) state = await this.checkDevice(state);
    while (!this.handler(state.phase).ends) state = await this.showPhase(state);
    this.handler(state.phase).show(this, state);
  }

  handler(phase) {
    const handler = this.handlers.get(phase);
    if (!handler) throw new Error(`unknown phase ${phase}`);
    return handler;
  }

  /**
   * Resolves with `state` once the window is large enough and has a fine pointer. Before
   * any trial the participant may instead end the study here: the server stores the
   * screened-out ending and the promise resolves with the done state.
   */
  checkDevice(state) {
    const canEnd = this.screenOutPhases.includes(state.phase);
    return new Promise((resolve, reject) => {
      const check = () => {
        const reason = unsupportedReason();
        if (!reason) {
          removeEventListener("resize", check);
          resolve(state);
          return;
        }
        $("unsupported-reason").textContent = reason.text;
        $("screen-out-block").hidden = !canEnd;
        $("screen-out").onclick = () => {
          removeEventListener("resize", check);
          $("screen-out").disabled = true;
          this.api.screenOut(reason.code).then(resolve, reject);
        };
        show("unsupported");
      };
      addEventListener("resize", check);
      check();
    });
  }

  /** Resume the token kept in sessionStorage (same recruitment), else start or resume on the server. */
  async ensureSession() {
    const recruitment = recruitmentFromUrl();
    const preview = previewFromUrl();
    const recruitmentKey = JSON.stringify({ recruitment, preview });
    const stored = JSON.parse(sessionStorage.getItem(this.storageKey) || "null");
    if (stored && stored.recruitmentKey === recruitmentKey) {
      this.api.token = stored.token;
      try {
        await this.api.state();
        return true;
      } catch (error) {
        if (!(error instanceof ApiError) || error.status >= 500) throw error;
        if (error.status === 410) {
          this.fail(forPeople(error.detail), { reload: false }); // replaced, or the study changed
          return false;
        }
        sessionStorage.removeItem(this.storageKey); // expired or unknown: start again
      }
    }
    try {
      const waiting = { onRetry: (error) => { $("screen-loading").textContent = error.detail ? forPeople(error.detail) : "Connecting to the study server\u2026"; } };
      const session = await this.api.startSession(recruitment, preview, waiting);
      this.api.token = session.session_token;
      sessionStorage.setItem(this.storageKey, JSON.stringify({ token: session.session_token, recruitmentKey }));
      return true;
    } catch (error) {
      if (error instanceof ApiError && error.status === 409) {
        // already completed or ended, or open with another attempt: the server says which
        this.fail(`This link cannot start the study again: ${error.detail}.`, { reload: false });
        return false;
      }
      if (error instanceof ApiError && error.status === 403) {
        this.fail(`This link cannot start the study: ${error.detail}. Please open the study again from the page where you found it.`, { reload: false });
        return false;
      }
      throw error;
    }
  }

  watchPage() {
    document.addEventListener("visibilitychange", () => {
      const hidden = document.visibilityState === "hidden";
      this.telemetry.log(hidden ? "visibility_hidden" : "visibility_shown");
      if (hidden) this.telemetry.flush({ keepalive: true });
    });
    // A reload or close may skip visibilitychange: send what is queued while the page goes.
    addEventListener("pagehide", () => this.telemetry.flush({ keepalive: true }));
    let resizeTimer = null;
    addEventListener("resize", () => {
      clearTimeout(resizeTimer);
      resizeTimer = setTimeout(() => this.telemetry.log("resize", { w: innerWidth, h: innerHeight }), 400);
    });
  }

  updateProgress({ done, total }) {
    $("progress").hidden = false;
    const bar = $("progress-bar");
    bar.setAttribute("aria-valuemax", String(total));
    bar.setAttribute("aria-valuenow", String(done));
    $("progress-fill").style.width = `${total ? (100 * done) / total : 0}%`;
    $("progress-text").textContent = `${done} of ${total} trials done`;
  }

  /** Show one phase; resolves with the state after the participant's answer is stored. */
  async showPhase(state) {
    if (state.progress) this.updateProgress(state.progress);
    const next = await this.handler(state.phase).show(this, state);
    return next?.phase ? next : this.api.state();
  }

  showConsent(step) {
    setProse($("consent-text"), step?.text ?? step?.consent_text ?? "");
    show("consent");
    const check = $("consent-check");
    const button = $("consent-agree");
    check.checked = false;
    button.disabled = true;
    check.onchange = () => { button.disabled = !check.checked; };
    const decline = $("consent-decline");
    decline.disabled = false;
    return new Promise((resolve, reject) => {
      button.onclick = () => {
        button.disabled = true;
        decline.disabled = true;
        this.api.consent(clientInfo()).then(resolve, reject);
      };
      decline.onclick = () => {
        button.disabled = true;
        decline.disabled = true;
        this.api.decline().then(resolve, reject);
      };
    });
  }

  showInstructions(step) {
    setProse($("instructions-text"), step?.text ?? step?.instructions_text ?? "");
    show("instructions");
    const player = new InstructionsDemo($("demo-canvas"), {
      onCaption: (text) => { $("demo-caption").textContent = text; },
    });
    player.play();
    $("demo-replay").onclick = () => player.play();
    const button = $("instructions-done");
    button.disabled = false;
    return new Promise((resolve, reject) => {
      button.onclick = () => {
        button.disabled = true;
        player.stop();
        this.api.instructionsDone().then(resolve, reject);
      };
    });
  }

  showTrial(state) {
    show("trial");
    const trial = new TrialScreen(state, this.api, this.telemetry);
    return trial.run();
  }

  showSurvey(step) {
    const questions = step?.questions ?? [];
    const container = $("survey-questions");
    container.replaceChildren(...questions.map(questionElement));
    show("survey");
    const form = $("survey-form");
    return new Promise((resolve, reject) => {
      form.onsubmit = (event) => {
        event.preventDefault();
        const { answers, missing } = collectAnswers(form, questions);
        if (missing.length) {
          $("survey-message").textContent = `Please answer: ${missing.join("; ")}`;
          return;
        }
        $("survey-message").textContent = "";
        form.querySelector("button[type=submit]").disabled = true;
        // the server refuses events once the session is done: send what is queued first
        this.telemetry.flush().then(() => this.api.survey(answers)).then(resolve, (error) => {
          form.querySelector("button[type=submit]").disabled = false;
          if (error instanceof ApiError && error.status < 500) $("survey-message").textContent = error.detail;
          else reject(error);
        });
      };
    });
  }

  /** The stored ending: its message and code, then the platform's redirect or MTurk hand-in form. */
  showDone(state) {
    if (state.progress) this.updateProgress(state.progress);
    const step = state.step || {};
    const finished = ["completed", "failed_checks", "excluded"].includes(step.outcome);
    $("done-heading").textContent = finished ? "Thank you!" : "The study has ended";
    $("done-message").textContent = step.message || (finished ? "You have finished the study." : "");
    $("completion-code").textContent = step.completion_code ?? "";
    $("code-block").hidden = !step.completion_code;
    show("done");
    this.telemetry.flush();
    if (step.mturk_submit) {
      this.showMturkForm(step.mturk_submit);
    } else if (step.redirect_url) {
      $("redirect-link").href = step.redirect_url;
      $("redirect-block").hidden = false;
      setTimeout(() => location.assign(step.redirect_url), REDIRECT_DELAY_MS);
    }
  }

  /** MTurk's ExternalQuestion hand-in: POST assignmentId (and the ending) to turkSubmitTo. */
  showMturkForm({ action, fields }) {
    const form = $("mturk-form");
    form.action = action;
    for (const [name, value] of Object.entries(fields)) {
      const input = document.createElement("input");
      input.type = "hidden";
      input.name = name;
      input.value = value;
      form.append(input);
    }
    form.hidden = false;
  }

  fail(text, { reload = true } = {}) {
    $("error-text").textContent = text;
    $("error-reload").hidden = !reload;
    $("error-reload").onclick = () => location.reload();
    show("error");
  }
}

/** One practice or main trial: watch the clips, then predict from each start state. */
class TrialScreen {
  constructor(state, api, telemetry) {
    this.trial = state.step;
    this.api = api;
    this.telemetry = telemetry;
    this.replays = 0;
    this.canvas = $("trial-canvas");
    this.player = new ClipPlayer(this.canvas, this.trial.scene, trialClips(this.trial), {
      onCaption: (text) => { $("trial-caption").textContent = text; },
    });
    this.input = null;
    const { done, total } = state.progress || { done: 0, total: 0 };
    $("trial-heading").textContent = this.trial.is_practice
      ? "Practice trial (not counted)"
      : `Trial ${done + 1} of ${total}`;
  }

  run() {
    return new Promise((resolve, reject) => {
      this.resolve = resolve;
      this.reject = reject;
      $("replay").onclick = () => this.replay();
      $("start-predicting").onclick = () => this.predict();
      $("undo").onclick = () => this.input?.undo();
      $("reset").onclick = () => this.input?.reset();
      $("next").onclick = () => this.confirm();
      this.watch();
    });
  }

  setMessage(text, kind = "ok") {
    const message = $("trial-message");
    message.textContent = text;
    message.className = `message ${kind}`;
  }

  async watch() {
    this.input?.pause();
    $("predict-controls").hidden = true;
    $("legend-predict").hidden = true;
    $("replay").disabled = true;
    $("start-predicting").disabled = true;
    $("start-predicting").hidden = false;
    this.setMessage("Watch the clips closely.");
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
    this.watch();
  }

  predict() {
    this.player.stop();
    $("start-predicting").hidden = true;
    $("start-predicting").disabled = true;
    $("predict-controls").hidden = false;
    $("legend-predict").hidden = false;
    $("replay").disabled = false;
    if (!this.input) {
      this.input = new PredictionInput(this.canvas, this.trial, {
        onChange: (input, options) => this.changed(input, options),
        onMessage: (text, kind) => this.setMessage(text, kind),
      });
    }
    this.input.start();
    this.changed(this.input);
    this.setMessage(`Click where the robot will be after each of the next ${this.trial.steps_to_predict} steps.`);
    this.canvas.focus({ preventScroll: true });
  }

  changed(input, { confirm = false } = {}) {
    const next = $("next");
    const states = this.trial.start_states.length;
    next.disabled = !input.stateDone();
    next.textContent = input.isLast() ? "Submit predictions" : `Next start position (${input.index + 2} of ${states})`;
    $("trial-caption").textContent = `Start position ${input.index + 1} of ${states}: `
      + `${input.current.length} of ${this.trial.steps_to_predict} positions placed.`;
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
    $("next").disabled = true;
    $("replay").disabled = true;
    this.body ??= { submission_id: newUuid(), ...this.input.body(this.replays) };
    this.setMessage("Saving your predictions…");
    try {
      const state = await this.api.predictions(this.body, {
        onRetry: () => this.setMessage("Connection problem: retrying to save your predictions…", "error"),
      });
      this.input.destroy();
      this.player.stop();
      this.setMessage("");
      this.resolve(state);
    } catch (error) {
      this.submitting = false;
      if (error instanceof ApiError && error.status < 500) {
        // The server refused this answer (e.g. it moved on): show why and follow its state.
        this.setMessage(`Not saved: ${error.detail}`, "error");
        this.input.destroy();
        this.player.stop();
        this.resolve(null);
      } else {
        this.reject(error);
      }
    }
  }
}

function setProse(element, text) {
  const paragraphs = String(text).split(/\n\s*\n/).map((block) => {
    const p = document.createElement("p");
    p.textContent = block.replace(/\s*\n\s*/g, " ").trim();
    return p;
  });
  element.replaceChildren(...paragraphs.filter((p) => p.textContent));
}

function questionElement(question) {
  const fieldset = document.createElement("fieldset");
  fieldset.className = "question";
  const legend = document.createElement("legend");
  legend.textContent = question.text + (question.required === false ? " (optional)" : "");
  fieldset.append(legend);
  if (question.kind === "text") {
    const area = document.createElement("textarea");
    area.name = question.key;
    area.rows = 3;
    area.maxLength = question.max_chars ?? 2000;
    area.setAttribute("aria-label", question.text);
    fieldset.append(area);
    return fieldset;
  }
  const values = question.kind === "likert"
    ? Array.from({ length: question.scale_max - question.scale_min + 1 }, (_, i) => String(question.scale_min + i))
    : question.options;
  const row = document.createElement("div");
  row.className = question.kind === "likert" ? "likert" : "choices";
  for (const value of values) {
    const label = document.createElement("label");
    const radio = document.createElement("input");
    radio.type = "radio";
    radio.name = question.key;
    radio.value = value;
    label.append(radio, ` ${value}`);
    row.append(label);
  }
  fieldset.append(row);
  return fieldset;
}

function collectAnswers(form, questions) {
  const data = new FormData(form);
  const answers = {};
  const missing = [];
  for (const question of questions) {
    const raw = (data.get(question.key) ?? "").toString().trim();
    if (!raw) {
      if (question.required !== false) missing.push(question.text);
      continue;
    }
    answers[question.key] = question.kind === "likert" ? Number(raw) : raw;
  }
  return { answers, missing };
}

const participantApp = new ParticipantApp($("app"));
participantApp.run().catch((error) => {
  console.error(error);
  if (error instanceof ApiError && error.status === 410) {
    participantApp.fail(forPeople(error.detail), { reload: false }); // replaced, or the study changed
    return;
  }
  participantApp.fail(`The study could not continue (${error.message}). Your answers so far are saved; reloading the page resumes where you were.`);
});
