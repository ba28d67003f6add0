// The participant app: one page driven by GET /api/session/state (token in X-Session-Token).
import { ApiError, StudyApi, newUuid } from "./api.js";
import { InstructionsDemo } from "./demo.js";
import { ClipPlayer, prefersReducedMotion, trialClips } from "./player.js";
import { PredictionInput } from "./predict.js";
import { drawBackground, label, prepareCanvas } from "./scene.js";
import { DEMO, say } from "./words.js";

const REDIRECT_DELAY_MS = 5000;
const SCREENS = ["loading", "unsupported", "consent", "instructions", "world", "practice-over", "trial", "pause",
  "survey", "done", "notice", "error"];
// the screens of a running study: a window made too small covers them until it is enlarged
const STUDY_SCREENS = ["consent", "instructions", "world", "practice-over", "trial", "pause", "survey"];
// This tab's id survives its reloads; the flag tells a duplicated tab (which copies
// sessionStorage while the original is open) to take its own. The takeover flag carries the
// person's choice "continue here" across the reload that follows it.
const TAB_KEY = "tomstudy.tab";
const TAB_OPEN_KEY = "tomstudy.tab.open";
const TAKEOVER_KEY = "tomstudy.tab.takeover";
const SAVE_RETRY_MAX_MS = 8000;

const $ = (id) => document.getElementById(id);

/**
 * One handler per phase the server sends (app/server/plan.py `Phase`; the page lists them in
 * its rules). `show` resolves with the next state once the participant's answer is
 * stored (or with null: read the state again); `ends` marks the phase that ends the session,
 * `beforeConsent` the one before which nothing is recorded.
 */
const PHASE_HANDLERS = {
  consent: { show: (app, state) => app.showConsent(state.step), beforeConsent: true },
  instructions: { show: (app, state) => app.showInstructions(state.step) },
  world_intro: { show: (app, state) => app.showWorld(state) },
  practice: { show: (app, state) => app.showTrial(state), trial: true },
  practice_over: { show: (app, state) => app.showPracticeOver(state) },
  trial: { show: (app, state) => app.showTrial(state), trial: true },
  survey: { show: (app, state) => app.showSurvey(state.step) },
  done: { show: (app, state) => app.showDone(state), ends: true },
};

/**
 * One check per reason the server takes for a screen-out (app/server/schemas.py
 * `ScreenOutReason`; the page lists them in its rules): given the smallest window the
 * server's prediction view is made for, why this device cannot run the study, or null.
 */
const DEVICE_CHECKS = {
  touch_only: () => (matchMedia("(any-pointer: coarse)").matches && !matchMedia("(any-pointer: fine)").matches
    ? "This study needs a mouse or touchpad: touch-only devices are not supported." : null),
  window_too_small: (min) => (innerWidth < min.width || innerHeight < min.height
    ? `Your browser window is ${innerWidth} × ${innerHeight} pixels; the study needs at least ${min.width} × ${min.height}.`
    : null),
};

/** The entries of `table` for `names`, in their order; throws on a name this script has none for. */
function entriesFor(table, names, what) {
  const missing = names.filter((name) => !Object.hasOwn(table, name));
  if (missing.length) throw new Error(`no ${what} for ${missing.join(", ")}`);
  return new Map(names.map((name) => [name, table[name]]));
}

/** The rules the server hands this page (app/server/routes/pages.py `PAGE_RULES`). */
function pageRules() {
  return JSON.parse($("page-rules").textContent);
}

function show(screen) {
  for (const name of SCREENS) $(`screen-${name}`).hidden = name !== screen;
}

/** Why this device cannot run the study ({code, text}: code as POST /screen-out takes it), or null. */
function unsupportedReason(checks, minWindow) {
  for (const [code, check] of checks) {
    const text = check(minWindow);
    if (text) return { code, text };
  }
  return null;
}

function clickCount(draft) {
  return draft.points.reduce((n, points) => n + points.length, 0);
}

/** What a refusal cost: "" when every click is on the server, else which were not saved. */
function unsavedText(clicks) {
  if (!clicks) return "";
  return clicks === 1 ? "Your last click in this tab was not saved." : `Your last ${clicks} clicks in this tab were not saved.`;
}

/** This tab's id (kept across its reloads; a duplicated tab gets its own). */
function currentTabId() {
  let id = sessionStorage.getItem(TAB_KEY);
  if (!id || sessionStorage.getItem(TAB_OPEN_KEY)) {
    id = newUuid().replaceAll("-", "");
    sessionStorage.setItem(TAB_KEY, id);
  }
  sessionStorage.setItem(TAB_OPEN_KEY, "1");
  addEventListener("pagehide", () => sessionStorage.removeItem(TAB_OPEN_KEY));
  addEventListener("pageshow", () => sessionStorage.setItem(TAB_OPEN_KEY, "1"));
  return id;
}

/**
 * Saves the current trial's clicks after every change (PUT .../draft), newest first: one
 * request at a time, retried while the connection is down, and the person is told whether
 * their clicks are saved. `onRefused(error)` gets a 4xx that no retry can change.
 */
class DraftSaver {
  constructor(api, seq, clicks, { onStatus, onRefused }) {
    this.api = api;
    this.seq = seq;
    this.savedClicks = clicks; // clicks in the newest draft the server has
    this.latest = null;
    this.sending = false;
    this.failures = 0;
    this.onStatus = onStatus;
    this.onRefused = onRefused;
    this.stopped = false;
  }

  save(draft) {
    this.seq += 1;
    this.latest = { ...draft, seq: this.seq };
    if (!this.failures) this.onStatus("Saving your clicks…", "ok"); // "saved" only once the server says so
    this.flush();
  }

  /** True while some click is not yet on the server. */
  pending() {
    return this.latest !== null || this.sending;
  }

  stop() {
    this.stopped = true;
  }

  async flush() {
    if (this.sending || !this.latest || this.stopped) return;
    const body = this.latest;
    this.sending = true;
    try {
      await this.api.saveDraft(body);
      this.savedClicks = clickCount(body);
      if (this.latest === body) this.latest = null;
      this.failures = 0;
      this.onStatus(this.latest ? "Saving your clicks…" : "Your clicks so far are saved.", "ok");
    } catch (error) {
      if (this.stopped) return; // the trial was submitted meanwhile: its answer is complete
      if (error instanceof ApiError && error.status < 500 && error.status !== 429) {
        this.stopped = true;
        this.onRefused(error, Math.max(0, clickCount(this.latest ?? body) - this.savedClicks));
        return;
      }
      this.failures += 1;
      this.onStatus("Connection problem: your clicks are kept in this window and will be saved as soon as the connection returns.", "error");
      await new Promise((resolve) => setTimeout(resolve, Math.min(SAVE_RETRY_MAX_MS, 500 * 2 ** this.failures)));
    } finally {
      this.sending = false;
    }
    this.flush();
  }
}

/**
 * Batches telemetry events and posts them, at most `perRequest` at a time; kept in memory
 * until the server takes them. `kinds` are the event kinds the server takes. Nothing is
 * recorded before consent (`consented()`): the server refuses such events too.
 */
class Telemetry {
  constructor(api, { kinds, perRequest }) {
    this.api = api;
    this.kinds = new Set(kinds);
    this.perRequest = perRequest;
    this.queue = [];
    this.timer = null;
    this.allowed = false;
  }

  /** The session has consented: events are recorded from now on. */
  consented() {
    this.allowed = true;
  }

  log(kind, data = {}) {
    if (!this.kinds.has(kind)) throw new Error(`the server takes no event ${kind}`);
    if (!this.allowed) return;
    this.queue.push({ submission_id: newUuid(), kind, t_client_ms: Date.now(), data });
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.flush(), 1000);
  }

  async flush({ keepalive = false } = {}) {
    if (!this.allowed || !this.api.token || !this.queue.length) return;
    const batch = this.queue.splice(0, this.perRequest);
    try {
      const response = await this.api.events(batch, { keepalive });
      if (response.status >= 500) this.queue.unshift(...batch);
    } catch {
      this.queue.unshift(...batch); // offline: try again with the next event
    }
  }
}

/** The URL's recruitment parameters among `names` (those the server takes). */
function recruitmentFromUrl(names) {
  const params = new URLSearchParams(location.search);
  const recruitment = {};
  for (const key of names) if (params.get(key)) recruitment[key] = params.get(key);
  return recruitment;
}

/**
 * Options for a press's write: while it is retried, `status` says why (offline, the server's
 * notice such as the study running its cap, or no answer); cleared now, so an earlier note does
 * not linger.
 */
function pressRetries(status) {
  status.textContent = "";
  const say = (error) => {
    status.textContent = navigator.onLine === false
      ? "You are offline. Your answer is kept and sent as soon as the connection returns; the study then continues by itself."
      : error?.notice?.text ?? "The study server cannot be reached right now. Trying again\u2026";
  };
  if (navigator.onLine === false) say();
  return { onRetry: say };
}

/** The researcher preview key of a lab member's test link, or null. */
function previewFromUrl() {
  return new URLSearchParams(location.search).get("preview");
}

/** A server refusal's message for a person: `field: message` without the field. */
function forPeople(detail) {
  return String(detail).replace(/^[\w.-]+: /, "");
}

function clientInfo(userAgentMaxChars) {
  return {
    screen_w: innerWidth,
    screen_h: innerHeight,
    touch_only: false,
    reduced_motion: prefersReducedMotion(),
    user_agent: navigator.userAgent.slice(0, userAgentMaxChars),
  };
}

class ParticipantApp {
  constructor(root) {
    const studyId = root.dataset.studyId;
    this.rules = pageRules();
    this.api = new StudyApi(studyId);
    this.telemetry = new Telemetry(this.api, { kinds: this.rules.event_kinds, perRequest: this.rules.events_per_request });
    this.storageKey = `tomstudy.${studyId}.session`;
    this.heartbeat = null;
    this.lost = false;
  }

  async run() {
    show("loading");
    this.handlers = entriesFor(PHASE_HANDLERS, this.rules.phases, "handler of phase");
    this.deviceChecks = entriesFor(DEVICE_CHECKS, this.rules.screen_out_reasons, "device check of screen-out reason");
    this.questionInputs = entriesFor(QUESTION_INPUTS, this.rules.survey_kinds, "input of survey question kind");
    const started = await this.ensureSession();
    if (!started) return;
    this.watchPage();
    let state = await this.api.state();
    if (!this.handler(state.phase).ends) {
      if (!(await this.claimTab())) return;
      state = await this.checkDevice(state);
      this.recheckWindow();
    }
    while (!this.handler(state.phase).ends) {
      if (!this.handler(state.phase).beforeConsent) this.telemetry.consented();
      const next = await this.showPhase(state);
      if (this.lost) return;
      if (this.pauseBetween(state, next)) {
        this.updateProgress(next.progress);
        await this.showPause(state.step, next.step);
      }
      state = next;
    }
    this.handler(state.phase).show(this, state);
  }

  /** A short break screen between two trials of the same part. */
  pauseBetween(state, next) {
    return this.handler(state.phase).trial && this.handlers.get(next.phase)?.trial
      && state.step?.part === next.step?.part;
  }

  showPause(done, next) {
    const what = done.is_practice ? `Practice trial ${done.number} of ${done.of}` : `Trial ${done.number} of ${done.of}`;
    $("pause-heading").textContent = `Part ${done.part} of ${done.parts} · ${what} saved`;
    const button = $("pause-done");
    button.textContent = next.is_practice ? "Continue to the next practice trial" : `Continue to trial ${next.number}`;
    show("pause");
    button.focus();
    return new Promise((resolve) => { button.onclick = resolve; });
  }

  /**
   * Make this tab the session's live one. If another tab holds it, say so and offer to
   * continue here (false: the page waits for that choice).
   */
  async claimTab() {
    this.api.tabId = currentTabId();
    const takeover = sessionStorage.getItem(TAKEOVER_KEY) === "1";
    sessionStorage.removeItem(TAKEOVER_KEY);
    try {
      const answer = await this.api.claimTab({ opened: true, takeover });
      addEventListener("pagehide", () => this.api.releaseTab());
      this.heartbeat = setInterval(() => this.beat(), answer.heartbeat_s * 1000);
      return true;
    } catch (error) {
      if (!(error instanceof ApiError && error.otherTab)) throw error;
      this.tabLost(error.notice);
      return false;
    }
  }

  /** Tell the server this tab is still the live one; it may answer that another took over. */
  beat() {
    this.api.claimTab().catch((error) => {
      if (error instanceof ApiError && error.otherTab) this.tabLost(error.notice);
    });
  }

  /**
   * Another tab holds the session: stop, say so plainly (and what of this tab's work was not
   * saved), and offer to continue here, which reloads the page as the live tab.
   */
  tabLost(notice, unsaved = "") {
    this.lost = true;
    clearInterval(this.heartbeat);
    this.trialScreen?.stop();
    this.showNotice(notice ?? { title: "The study is open in another tab", text: "", action: "takeover" }, {
      extra: unsaved,
      button: "Continue here instead",
      onAction: () => {
        sessionStorage.setItem(TAKEOVER_KEY, "1");
        location.reload();
      },
    });
  }

  /** A plain-language notice; with `onAction`, one button (else the page stays here). */
  showNotice(notice, { extra = "", button = "", onAction = null } = {}) {
    $("notice-title").textContent = notice.title;
    $("notice-text").textContent = notice.text;
    $("notice-extra").textContent = extra;
    $("notice-extra").hidden = !extra;
    const action = $("notice-action");
    action.hidden = !onAction;
    action.textContent = button;
    action.onclick = onAction;
    $("progress").hidden = true;
    show("notice");
    if (onAction) action.focus();
  }

  /** The person must see `notice` before the study goes on; resolves when they continue. */
  confirmNotice(notice, button = "Continue") {
    return new Promise((resolve) => {
      this.showNotice(notice, { button, onAction: resolve });
    });
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
    const canEnd = this.rules.screen_out_phases.includes(state.phase);
    return new Promise((resolve, reject) => {
      const check = () => {
        const reason = unsupportedReason(this.deviceChecks, this.rules.min_window);
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

  /**
   * Once the study runs, a window made smaller than the display check allows covers the
   * screen with the reason until it is large enough again, then the same screen comes back
   * as it was (this listener runs before the canvases' own, which then redraw at full size).
   */
  recheckWindow() {
    const check = this.deviceChecks.get("window_too_small");
    if (!check) return;
    let covered = null;
    addEventListener("resize", () => {
      const text = check(this.rules.min_window);
      if (text) {
        covered ??= SCREENS.find((name) => !$(`screen-${name}`).hidden);
        if (!STUDY_SCREENS.includes(covered)) {
          covered = null;
          return;
        }
        $("unsupported-title").textContent = "Please make the window larger";
        $("unsupported-help").textContent = "Your answers so far are saved. When the window is large enough again, the study continues where you were.";
        $("unsupported-reason").textContent = text;
        $("screen-out-block").hidden = true;
        show("unsupported");
      } else if (covered) {
        if (!$("screen-unsupported").hidden) show(covered);
        covered = null;
      }
    });
  }

  /** Resume the token kept in sessionStorage (same recruitment), else start or resume on the server. */
  async ensureSession() {
    const recruitment = recruitmentFromUrl(this.rules.recruitment_params);
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
        if (error.status === 410) { // replaced, or the study changed: the notice says so
          this.failWith(error);
          return false;
        }
        sessionStorage.removeItem(this.storageKey); // expired or unknown: start again
      }
    }
    try {
      const waiting = { onRetry: (error) => { $("screen-loading").textContent = error.notice?.text ?? (error.detail ? forPeople(error.detail) : "Connecting to the study server\u2026"); } };
      const session = await this.api.startSession(recruitment, preview, waiting);
      this.api.token = session.session_token;
      sessionStorage.setItem(this.storageKey, JSON.stringify({ token: session.session_token, recruitmentKey }));
      return true;
    } catch (error) {
      // a link the study cannot start from: the server's plain-language notice says what to do
      if (error instanceof ApiError && error.status < 500 && error.notice) {
        this.showNotice(error.notice);
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
    if (this.lost) return;
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
    showConsentForm($("consent-text"), step);
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
        this.api.consent(clientInfo(this.rules.user_agent_max_chars), pressRetries($("consent-status"))).then(resolve, reject);
      };
      decline.onclick = () => {
        button.disabled = true;
        decline.disabled = true;
        this.api.decline(pressRetries($("consent-status"))).then(resolve, reject);
      };
    });
  }

  showInstructions(step) {
    setProse($("instructions-text"), step?.text ?? step?.instructions_text ?? "");
    show("instructions");
    const player = new InstructionsDemo($("demo-canvas"), DEMO, {
      rules: this.rules.predictions,
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
        this.api.instructionsDone(pressRetries($("instructions-status"))).then(resolve, reject);
      };
    });
  }

  /** A part's first screen: which part, its world explained and drawn, what the part holds. */
  showWorld(state) {
    const step = state.step;
    $("world-part").textContent = step.part > 1 ? `Part ${step.part} of ${step.parts}: a new world` : `Part ${step.part} of ${step.parts}`;
    $("world-title").textContent = step.title;
    setProse($("world-text"), step.text);
    const practice = step.practice_trials;
    $("world-plan").textContent = practice
      ? `This part starts with ${practice === 1 ? "a practice trial, which does" : `${practice} practice trials, which do`} not count, then ${step.trials} trials that do.`
      : `This part has ${step.trials} trials.`;
    const button = $("world-done");
    button.textContent = practice ? "Start the practice" : "Start trial 1";
    show("world");
    drawWorldMap($("world-canvas"), step.scene);
    return this.continueFrom(state.phase, button);
  }

  showPracticeOver(state) {
    const step = state.step;
    $("practice-over-part").textContent = `Part ${step.part} of ${step.parts}: ${step.title}`;
    $("practice-over-text").textContent = `That was the practice. The next ${step.trials} trials count; `
      + `they are numbered 1 to ${step.trials}. After each one you can take a short break.`;
    show("practice-over");
    return this.continueFrom(state.phase, $("practice-over-done"));
  }

  /** Resolve with the next state once `button` is pressed and the server has moved on (its
   * screen's status line says so while it cannot be reached). */
  continueFrom(phase, button) {
    button.disabled = false;
    button.focus();
    const status = button.closest("section").querySelector(".press-status");
    status.textContent = "";
    return new Promise((resolve, reject) => {
      button.onclick = () => {
        button.disabled = true;
        this.api.continueFrom(phase, pressRetries(status)).then(resolve, reject);
      };
    });
  }

  showTrial(state) {
    show("trial");
    this.trialScreen = new TrialScreen(state, this);
    return this.trialScreen.run();
  }

  showSurvey(step) {
    const questions = step?.questions ?? [];
    const container = $("survey-questions");
    container.replaceChildren(...questions.map((question) => questionElement(question, this.questionInputs)));
    show("survey");
    const form = $("survey-form");
    return new Promise((resolve, reject) => {
      form.onsubmit = (event) => {
        event.preventDefault();
        const { answers, missing } = collectAnswers(form, questions, this.questionInputs);
        if (missing.length) {
          $("survey-message").textContent = `Please answer: ${missing.join("; ")}`;
          return;
        }
        $("survey-message").textContent = "";
        form.querySelector("button[type=submit]").disabled = true;
        // the server refuses events once the session is done: send what is queued first
        const retries = pressRetries($("survey-message"));
        this.telemetry.flush().then(() => this.api.survey(answers, retries)).then(resolve, (error) => {
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
    const finished = this.rules.finished_outcomes.includes(step.outcome);
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

  /** What an error that ended the run means for the person. */
  failWith(error) {
    if (error instanceof ApiError && error.otherTab) {
      this.tabLost(error.notice);
    } else if (error instanceof ApiError && error.notice && error.status < 500) {
      this.showNotice(error.notice); // a replaced attempt, a changed study: what to do now
    } else {
      this.fail(`The study could not continue (${error.message}). Your answers so far are saved; reloading the page resumes where you were.`);
    }
  }
}

/** The scene of a part, whole, with what is in it named: goals, obstacles, lanes. */
function drawWorldMap(canvas, scene) {
  const { ctx, view } = prepareCanvas(canvas, scene);
  drawBackground(ctx, view, scene);
  (scene.obstacles || []).forEach((o) => {
    const [x, y] = view.toPx([o.x_m, o.y_m]);
    label(ctx, "obstacle", x, y, "#111111", 12);
  });
  (scene.lanes || []).forEach((lane, k) => {
    const [x, y] = view.toPx([scene.bounds.x_min_m, lane.y_center_m]);
    label(ctx, `lane ${k + 1}`, x + 34, y, "#111111", 12);
  });
  if (scene.lanes?.length) {
    const [x, y] = view.toPx([scene.bounds.x_max_m, scene.bounds.y_min_m]);
    label(ctx, "cars drive this way →", x - 80, y + 10, "#111111", 12);
  }
}

/**
 * One practice or main trial: watch the clips, then predict from each start state. Every
 * change is saved as a draft, so a reload (or a new tab that takes over) resumes at the
 * same start state with the same clicks, without the clips again.
 */
class TrialScreen {
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
    await this.app.confirmNotice({
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

/** The consent page: its typed sections (app/study/consent.py), each a heading and prose
 * with e-mail addresses as links, or a study's older free text. */
function showConsentForm(element, step) {
  const sections = step?.sections ?? [];
  if (!sections.length) {
    setProse(element, step?.text ?? step?.consent_text ?? "");
    return;
  }
  element.replaceChildren(...sections.flatMap(({ heading, text }) => {
    const title = document.createElement("h3");
    title.textContent = heading;
    const body = document.createElement("div");
    setProse(body, text);
    body.querySelectorAll("p").forEach(linkEmails);
    return [title, ...body.children];
  }));
}

/** Turn the e-mail addresses in a paragraph's text into mailto links. */
function linkEmails(paragraph) {
  const parts = paragraph.textContent.split(/([^\s@,;()]+@[^\s@,;()]+\.[A-Za-z]{2,})/);
  if (parts.length === 1) return;
  paragraph.replaceChildren(...parts.map((part, i) => {
    if (i % 2 === 0) return document.createTextNode(part);
    const link = document.createElement("a");
    link.href = `mailto:${part}`;
    link.textContent = part;
    return link;
  }));
}

function setProse(element, text) {
  const paragraphs = String(text).split(/\n\s*\n/).map((block) => {
    const p = document.createElement("p");
    p.textContent = block.replace(/\s*\n\s*/g, " ").trim();
    return p;
  });
  element.replaceChildren(...paragraphs.filter((p) => p.textContent));
}

/**
 * One input per kind of survey question the server has (app/study/config.py
 * `SurveyQuestion.kind`; the page lists them in its rules): its element, and the answer
 * from the form's value.
 */
const QUESTION_INPUTS = {
  likert: {
    element: (question) => choiceRow(question, "likert", Array.from(
      { length: question.scale_max - question.scale_min + 1 }, (_, i) => String(question.scale_min + i))),
    answer: Number,
  },
  text: { element: textArea, answer: String },
  choice: { element: (question) => choiceRow(question, "choices", question.options), answer: String },
};

function questionElement(question, inputs) {
  const fieldset = document.createElement("fieldset");
  fieldset.className = "question";
  const legend = document.createElement("legend");
  legend.textContent = question.text + (question.required === false ? " (optional)" : "");
  fieldset.append(legend, inputs.get(question.kind).element(question));
  return fieldset;
}

function textArea(question) {
  const area = document.createElement("textarea");
  area.name = question.key;
  area.rows = 3;
  area.maxLength = question.max_chars;
  area.setAttribute("aria-label", question.text);
  return area;
}

/** One radio button per value, in a row of class `className`. */
function choiceRow(question, className, values) {
  const row = document.createElement("div");
  row.className = className;
  for (const value of values) {
    const label = document.createElement("label");
    const radio = document.createElement("input");
    radio.type = "radio";
    radio.name = question.key;
    radio.value = value;
    label.append(radio, ` ${value}`);
    row.append(label);
  }
  return row;
}

function collectAnswers(form, questions, inputs) {
  const data = new FormData(form);
  const answers = {};
  const missing = [];
  for (const question of questions) {
    const raw = (data.get(question.key) ?? "").toString().trim();
    if (!raw) {
      if (question.required !== false) missing.push(question.text);
      continue;
    }
    answers[question.key] = inputs.get(question.kind).answer(raw);
  }
  return { answers, missing };
}

const participantApp = new ParticipantApp($("app"));
participantApp.run().catch((error) => {
  console.error(error);
  participantApp.failWith(error);
});
