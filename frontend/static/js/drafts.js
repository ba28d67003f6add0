// A trial's clicks saved as a draft after every change, so a reload or another tab resumes them.
import { ApiError } from "./api.js";

const SAVE_RETRY_MAX_MS = 8000;

/** How many clicks a draft holds, over all its start states. */
export function clickCount(draft) {
  return draft.points.reduce((n, points) => n + points.length, 0);
}

/** What a refusal cost: "" when every click is on the server, else which were not saved. */
export function unsavedText(clicks) {
  if (!clicks) return "";
  return clicks === 1 ? "Your last click in this tab was not saved." : `Your last ${clicks} clicks in this tab were not saved.`;
}

/**
 * Saves the current trial's clicks after every change (PUT .../draft), newest first: one
 * request at a time, retried while the connection is down, and the person is told whether
 * their clicks are saved. `onRefused(error)` gets a 4xx that no retry can change.
 */
export class DraftSaver {
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
