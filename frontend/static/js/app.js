// The participant app: one page driven by GET /api/session/state (token in X-Session-Token).
import { ApiError, StudyApi } from "./api.js";
import { showConsent } from "./consent.js";
import { DEVICE_CHECKS, coverWhileTooSmall, waitForDevice } from "./device.js";
import { showDone } from "./ending.js";
import { showInstructions, showPracticeOver, showWorld } from "./intro.js";
import { $, fail, show, showNotice } from "./page.js";
import { ensureSession } from "./session.js";
import { QUESTION_INPUTS, showSurvey } from "./survey.js";
import { LiveTab, takeOver } from "./tab.js";
import { Telemetry, watchPage } from "./telemetry.js";
import { TrialScreen, showPause } from "./trial.js";

/**
 * One handler per phase the server sends (app/server/flow/plan.py `Phase`; the page lists them in
 * its rules). `show` resolves with the next state once the participant's answer is
 * stored (or with null: read the state again); `ends` marks the phase that ends the session,
 * `beforeConsent` the one before which nothing is recorded.
 */
const PHASE_HANDLERS = {
  consent: { show: (app, state) => showConsent(app, state.step), beforeConsent: true },
  instructions: { show: (app, state) => showInstructions(app, state.step) },
  world_intro: { show: (app, state) => showWorld(app, state) },
  practice: { show: (app, state) => app.showTrial(state), trial: true },
  practice_over: { show: (app, state) => showPracticeOver(app, state) },
  trial: { show: (app, state) => app.showTrial(state), trial: true },
  survey: { show: (app, state) => showSurvey(app, state.step) },
  done: { show: (app, state) => showDone(app, state), ends: true },
};

/** The entries of `table` for `names`, in their order; throws on a name this script has none for. */
function entriesFor(table, names, what) {
  const missing = names.filter((name) => !Object.hasOwn(table, name));
  if (missing.length) throw new Error(`no ${what} for ${missing.join(", ")}`);
  return new Map(names.map((name) => [name, table[name]]));
}

/** The rules the server hands this page (app/http/routes/pages.py `PAGE_RULES`). */
function pageRules() {
  return JSON.parse($("page-rules").textContent);
}

/** The page's flow: the session, this tab's claim and the device, then one screen per phase. */
class ParticipantApp {
  constructor(root) {
    const studyId = root.dataset.studyId;
    this.rules = pageRules();
    this.api = new StudyApi(studyId);
    this.telemetry = new Telemetry(this.api, { kinds: this.rules.event_kinds, perRequest: this.rules.events_per_request });
    this.tab = new LiveTab(this.api, (notice) => this.tabLost(notice));
    this.storageKey = `tomstudy.${studyId}.session`;
    this.lost = false;
  }

  async run() {
    show("loading");
    this.handlers = entriesFor(PHASE_HANDLERS, this.rules.phases, "handler of phase");
    this.deviceChecks = entriesFor(DEVICE_CHECKS, this.rules.screen_out_reasons, "device check of screen-out reason");
    this.questionInputs = entriesFor(QUESTION_INPUTS, this.rules.survey_kinds, "input of survey question kind");
    const started = await ensureSession(this);
    if (!started) return;
    watchPage(this.telemetry);
    let state = await this.api.state();
    if (!this.handler(state.phase).ends) {
      if (!(await this.tab.claim())) return;
      state = await waitForDevice(this, state);
      coverWhileTooSmall(this);
    }
    while (!this.handler(state.phase).ends) {
      if (!this.handler(state.phase).beforeConsent) this.telemetry.consented();
      const next = await this.showPhase(state);
      if (this.lost) return;
      if (this.pauseBetween(state, next)) {
        this.updateProgress(next.progress);
        await showPause(state.step, next.step);
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

  /**
   * Another tab holds the session: stop, say so plainly (and what of this tab's work was not
   * saved), and offer to continue here, which reloads the page as the live tab.
   */
  tabLost(notice, unsaved = "") {
    this.lost = true;
    this.tab.stop();
    this.trialScreen?.stop();
    showNotice(notice ?? { title: "The study is open in another tab", text: "", action: "takeover" }, {
      extra: unsaved,
      button: "Continue here instead",
      onAction: takeOver,
    });
  }

  handler(phase) {
    const handler = this.handlers.get(phase);
    if (!handler) throw new Error(`unknown phase ${phase}`);
    return handler;
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

  showTrial(state) {
    show("trial");
    this.trialScreen = new TrialScreen(state, this);
    return this.trialScreen.run();
  }

  /** What an error that ended the run means for the person. */
  failWith(error) {
    if (error instanceof ApiError && error.otherTab) {
      this.tabLost(error.notice);
    } else if (error instanceof ApiError && error.notice && error.status < 500) {
      showNotice(error.notice); // a replaced attempt, a changed study: what to do now
    } else {
      fail(`The study could not continue (${error.message}). Your answers so far are saved; reloading the page resumes where you were.`);
    }
  }
}

const participantApp = new ParticipantApp($("app"));
participantApp.run().catch((error) => {
  console.error(error);
  participantApp.failWith(error);
});
