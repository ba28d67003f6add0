// Thin client for the study HTTP API (app/http/API.md). No state beyond the token.

/**
 * An HTTP answer outside 2xx, with the server's `detail` message and, for refusals a
 * participant can meet, its plain-language `notice` ({title, text, action}).
 */
export class ApiError extends Error {
  constructor(status, detail, notice = null) {
    super(`${status}: ${detail}`);
    this.status = status;
    this.detail = detail;
    this.notice = notice;
  }

  /** True when the server refused because another tab is the session's live one. */
  get otherTab() {
    return this.status === 409 && String(this.detail).startsWith("tab:");
  }
}

/** A random RFC 4122 version-4 UUID (crypto.randomUUID needs a secure context). */
export function newUuid() {
  if (globalThis.crypto && typeof crypto.randomUUID === "function") return crypto.randomUUID();
  const bytes = crypto.getRandomValues(new Uint8Array(16));
  bytes[6] = (bytes[6] & 0x0f) | 0x40;
  bytes[8] = (bytes[8] & 0x3f) | 0x80;
  const hex = [...bytes].map((b) => b.toString(16).padStart(2, "0")).join("");
  return `${hex.slice(0, 8)}-${hex.slice(8, 12)}-${hex.slice(12, 16)}-${hex.slice(16, 20)}-${hex.slice(20)}`;
}

function detailText(detail) {
  if (typeof detail === "string") return detail;
  if (Array.isArray(detail)) {
    return detail.map((d) => `${(d.loc || []).join(".")}: ${d.msg}`).join("; ");
  }
  return JSON.stringify(detail);
}

/** Send one JSON request; resolve with the parsed body, reject with ApiError or TypeError. */
export async function requestJson(method, path, body, headers = {}) {
  const init = { method, headers: { Accept: "application/json", ...headers } };
  if (body !== undefined) {
    init.headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const response = await fetch(path, init);
  const text = await response.text();
  let parsed = null;
  try {
    parsed = text ? JSON.parse(text) : null;
  } catch {
    parsed = { detail: text };
  }
  if (!response.ok) {
    throw new ApiError(response.status, parsed?.message ?? detailText(parsed?.detail ?? text), parsed?.notice ?? null);
  }
  return parsed;
}

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

/**
 * Send a write until the server acknowledges it with a 2xx.
 * Network failures and 5xx/429 are retried with the same body (same submission_id),
 * so the server stores it once; other 4xx are final and rethrown.
 */
export async function sendUntilAcknowledged(method, path, body, { onRetry, maxDelayMs = 8000, headers = {} } = {}) {
  for (let attempt = 0; ; attempt += 1) {
    try {
      return await requestJson(method, path, body, headers);
    } catch (error) {
      const retryable = !(error instanceof ApiError) || error.status >= 500 || error.status === 429;
      if (!retryable) throw error;
      onRetry?.(error, attempt);
      await sleep(Math.min(maxDelayMs, 500 * 2 ** attempt));
    }
  }
}

const enc = encodeURIComponent;

/**
 * The participant side of the API, bound to one session token once it is known. The token
 * travels in the X-Session-Token header, never in a URL (proxies and history keep URLs).
 * Writes also name this page's tab (`tabId`, header X-Tab-Id), so the server refuses them
 * once another tab has taken the session over (app/server/flow/tabs.py).
 */
export class StudyApi {
  constructor(studyId) {
    this.studyId = studyId;
    this.token = null;
    this.tabId = null;
  }

  startSession(recruitment, preview = null, options = {}) {
    const body = { study_id: this.studyId, recruitment };
    if (preview) body.preview = preview;
    return sendUntilAcknowledged("POST", "/api/sessions", body, options);
  }

  /** The session token, and this tab's id on writes. */
  headers({ write = false } = {}) {
    const headers = { "X-Session-Token": this.token };
    if (write && this.tabId) headers["X-Tab-Id"] = this.tabId;
    return headers;
  }

  /** A write retried until acknowledged, naming this tab. */
  write(what, body, options = {}, method = "POST") {
    return sendUntilAcknowledged(method, `/api/session/${what}`, body, { ...options, headers: this.headers({ write: true }) });
  }

  state() {
    return requestJson("GET", "/api/session/state", undefined, this.headers());
  }

  /** Consent; the device info (`client`) is stored from here on, never before. */
  consent(client, options) {
    return this.write("consent", { submission_id: newUuid(), agree: true, client }, options);
  }

  decline(options) {
    return this.write("decline", { submission_id: newUuid() }, options);
  }

  screenOut(reason, options) {
    return this.write("screen-out", { submission_id: newUuid(), reason }, options);
  }

  instructionsDone(options) {
    return this.write("instructions", { submission_id: newUuid() }, options);
  }

  /** `body` must already carry its submission_id so a retry reuses it. */
  predictions(body, options) {
    return this.write("predictions", body, options);
  }

  /** A part's screen was read (world_intro or practice_over). */
  continueFrom(phase, options) {
    return this.write("continue", { submission_id: newUuid(), phase }, options);
  }

  /** Keep the current trial's clicks so far (one attempt: the caller retries the newest). */
  saveDraft(draft) {
    return requestJson("PUT", "/api/session/draft", draft, this.headers({ write: true }));
  }

  /** Claim the session for this tab (on load with `opened`, then as a heartbeat). */
  claimTab({ takeover = false, opened = false } = {}) {
    return requestJson("POST", "/api/session/tab", { tab_id: this.tabId, takeover, opened, t_client_ms: Date.now() }, this.headers());
  }

  /** The page is going away: let another tab claim the session without asking. A keepalive
   * fetch rather than sendBeacon, which cannot carry the token header. */
  releaseTab() {
    if (!this.token || !this.tabId) return;
    fetch("/api/session/tab/release", {
      method: "POST",
      headers: { "Content-Type": "application/json", ...this.headers() },
      body: JSON.stringify({ tab_id: this.tabId }),
      keepalive: true,
    }).catch(() => {});
  }

  survey(answers, options) {
    return this.write("survey", { submission_id: newUuid(), answers }, options);
  }

  events(events, { keepalive = false } = {}) {
    return fetch("/api/session/events", {
      method: "POST",
      headers: { "Content-Type": "application/json", ...this.headers() },
      body: JSON.stringify({ events }),
      keepalive,
    });
  }
}

/** The researcher side: every call carries the bearer token. */
export class ResearcherApi {
  constructor(token) {
    this.token = token;
  }

  auth() {
    return { Authorization: `Bearer ${this.token}` };
  }

  summary(studyId) {
    const query = studyId ? `?study_id=${enc(studyId)}` : "";
    return requestJson("GET", `/api/researcher/summary${query}`, undefined, this.auth());
  }

  /** Withdraw one participant (`kind`: external_id or participant_id); the audit line. */
  withdraw(studyId, kind, id) {
    return requestJson("POST", "/api/researcher/withdrawals", { study_id: studyId, [kind]: id }, this.auth());
  }

  withdrawals(studyId) {
    return requestJson("GET", `/api/researcher/withdrawals/audit?study_id=${enc(studyId)}`, undefined, this.auth());
  }

  /** One export (`what`: predictions, survey, events or participants) as a Blob. */
  exportCsv(studyId, what = "predictions") {
    return this.exportFile(studyId, `${enc(what)}.csv`);
  }

  /** One export's codebook (its Frictionless datapackage.json) as a Blob. */
  exportPackage(studyId, what = "predictions") {
    return this.exportFile(studyId, `${enc(what)}.datapackage.json`);
  }

  async exportFile(studyId, name) {
    const query = studyId ? `?study_id=${enc(studyId)}` : "";
    const response = await fetch(`/api/researcher/export/${name}${query}`, { headers: this.auth() });
    if (!response.ok) throw new ApiError(response.status, await response.text());
    return response.blob();
  }
}
