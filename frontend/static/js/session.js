// This tab's session: the token kept for the link's recruitment, else one started on the server.
import { ApiError } from "./api.js";
import { $, showNotice } from "./page.js";

/** The URL's recruitment parameters among `names` (those the server takes). */
function recruitmentFromUrl(names) {
  const params = new URLSearchParams(location.search);
  const recruitment = {};
  for (const key of names) if (params.get(key)) recruitment[key] = params.get(key);
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

/**
 * Resume the token kept in sessionStorage (same recruitment), else start or resume on the
 * server; false when the page says instead why the study cannot go on.
 */
export async function ensureSession(app) {
  const recruitment = recruitmentFromUrl(app.rules.recruitment_params);
  const preview = previewFromUrl();
  const recruitmentKey = JSON.stringify({ recruitment, preview });
  const stored = JSON.parse(sessionStorage.getItem(app.storageKey) || "null");
  if (stored && stored.recruitmentKey === recruitmentKey) {
    const resumed = await resumeStored(app, stored.token);
    if (resumed !== null) return resumed;
  }
  return startSession(app, recruitment, preview, recruitmentKey);
}

/** The kept token: true if it still holds, false if it ended for good (the notice says so),
 * null if it is gone and a session is to be started again. */
async function resumeStored(app, token) {
  app.api.token = token;
  try {
    await app.api.state();
    return true;
  } catch (error) {
    if (!(error instanceof ApiError) || error.status >= 500) throw error;
    if (error.status === 410) { // replaced, or the study changed: the notice says so
      app.failWith(error);
      return false;
    }
    sessionStorage.removeItem(app.storageKey); // expired or unknown: start again
    return null;
  }
}

/** Start (or resume) the link's session on the server and keep its token for this tab. */
async function startSession(app, recruitment, preview, recruitmentKey) {
  try {
    const session = await app.api.startSession(recruitment, preview, { onRetry: showWaiting });
    app.api.token = session.session_token;
    sessionStorage.setItem(app.storageKey, JSON.stringify({ token: session.session_token, recruitmentKey }));
    return true;
  } catch (error) {
    // a link the study cannot start from: the server's plain-language notice says what to do
    if (error instanceof ApiError && error.status < 500 && error.notice) {
      showNotice(error.notice);
      return false;
    }
    throw error;
  }
}

/** While the session cannot start yet: the server's notice or refusal, else that the page connects. */
function showWaiting(error) {
  $("screen-loading").textContent = error.notice?.text ?? (error.detail ? forPeople(error.detail) : "Connecting to the study server\u2026");
}
