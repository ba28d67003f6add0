// The page's telemetry: events batched and posted after consent, and the page's own (visibility, size).
import { newUuid } from "./api.js";

/**
 * Batches telemetry events and posts them, at most `perRequest` at a time; kept in memory
 * until the server takes them. `kinds` are the event kinds the server takes. Nothing is
 * recorded before consent (`consented()`): the server refuses such events too.
 */
export class Telemetry {
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

/** Log the page going out of sight and back and its resizes; send what is queued as it goes. */
export function watchPage(telemetry) {
  document.addEventListener("visibilitychange", () => {
    const hidden = document.visibilityState === "hidden";
    telemetry.log(hidden ? "visibility_hidden" : "visibility_shown");
    if (hidden) telemetry.flush({ keepalive: true });
  });
  // A reload or close may skip visibilitychange: send what is queued while the page goes.
  addEventListener("pagehide", () => telemetry.flush({ keepalive: true }));
  let resizeTimer = null;
  addEventListener("resize", () => {
    clearTimeout(resizeTimer);
    resizeTimer = setTimeout(() => telemetry.log("resize", { w: innerWidth, h: innerHeight }), 400);
  });
}
