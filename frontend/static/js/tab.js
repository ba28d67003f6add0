// This tab as the session's live one: its id across reloads, its claim and heartbeat, a takeover.
import { ApiError, newUuid } from "./api.js";

// This tab's id survives its reloads; the flag tells a duplicated tab (which copies
// sessionStorage while the original is open) to take its own. The takeover flag carries the
// person's choice "continue here" across the reload that follows it.
const TAB_KEY = "tomstudy.tab";
const TAB_OPEN_KEY = "tomstudy.tab.open";
const TAKEOVER_KEY = "tomstudy.tab.takeover";

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

/** Whether the person chose "continue here" before this load (read once: the choice is used up). */
function takeoverChosen() {
  const takeover = sessionStorage.getItem(TAKEOVER_KEY) === "1";
  sessionStorage.removeItem(TAKEOVER_KEY);
  return takeover;
}

/** Continue in this tab: reload it as the session's live one. */
export function takeOver() {
  sessionStorage.setItem(TAKEOVER_KEY, "1");
  location.reload();
}

/**
 * Keeps this tab the session's live one: claims it, then beats at the server's interval.
 * `onLost(notice)` hears that another tab holds the session.
 */
export class LiveTab {
  constructor(api, onLost) {
    this.api = api;
    this.onLost = onLost;
    this.heartbeat = null;
  }

  /**
   * Make this tab the session's live one. If another tab holds it, `onLost` says so and
   * offers to continue here (false: the page waits for that choice).
   */
  async claim() {
    this.api.tabId = currentTabId();
    const takeover = takeoverChosen();
    try {
      const answer = await this.api.claimTab({ opened: true, takeover });
      addEventListener("pagehide", () => this.api.releaseTab());
      this.heartbeat = setInterval(() => this.beat(), answer.heartbeat_s * 1000);
      return true;
    } catch (error) {
      if (!(error instanceof ApiError && error.otherTab)) throw error;
      this.onLost(error.notice);
      return false;
    }
  }

  /** Tell the server this tab is still the live one; it may answer that another took over. */
  beat() {
    this.api.claimTab().catch((error) => {
      if (error instanceof ApiError && error.otherTab) this.onLost(error.notice);
    });
  }

  stop() {
    clearInterval(this.heartbeat);
  }
}
