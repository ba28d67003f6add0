// The participant page's screens: show one (or a notice, an error), text as paragraphs, press retries.
export const $ = (id) => document.getElementById(id);

export const SCREENS = ["loading", "unsupported", "consent", "instructions", "world", "practice-over", "trial", "pause",
  "survey", "done", "notice", "error"];
// the screens of a running study: a window made too small covers them until it is enlarged
export const STUDY_SCREENS = ["consent", "instructions", "world", "practice-over", "trial", "pause", "survey"];

/** Show `screen`, hide every other. */
export function show(screen) {
  for (const name of SCREENS) $(`screen-${name}`).hidden = name !== screen;
}

/** The screen shown now (undefined while none is). */
export function shownScreen() {
  return SCREENS.find((name) => !$(`screen-${name}`).hidden);
}

/** A plain-language notice; with `onAction`, one button (else the page stays here). */
export function showNotice(notice, { extra = "", button = "", onAction = null } = {}) {
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
export function confirmNotice(notice, button = "Continue") {
  return new Promise((resolve) => {
    showNotice(notice, { button, onAction: resolve });
  });
}

/** The error screen: `text`, and (with `reload`) a button that reloads the page. */
export function fail(text, { reload = true } = {}) {
  $("error-text").textContent = text;
  $("error-reload").hidden = !reload;
  $("error-reload").onclick = () => location.reload();
  show("error");
}

/** `text` as the paragraphs of `element` (blank lines part them). */
export function setProse(element, text) {
  const paragraphs = String(text).split(/\n\s*\n/).map((block) => {
    const p = document.createElement("p");
    p.textContent = block.replace(/\s*\n\s*/g, " ").trim();
    return p;
  });
  element.replaceChildren(...paragraphs.filter((p) => p.textContent));
}

/**
 * Options for a press's write: while it is retried, `status` says why (offline, the server's
 * notice such as the study running its cap, or no answer); cleared now, so an earlier note does
 * not linger.
 */
export function pressRetries(status) {
  status.textContent = "";
  const say = (error) => {
    status.textContent = navigator.onLine === false
      ? "You are offline. Your answer is kept and sent as soon as the connection returns; the study then continues by itself."
      : error?.notice?.text ?? "The study server cannot be reached right now. Trying again\u2026";
  };
  if (navigator.onLine === false) say();
  return { onRetry: say };
}
