// The study's end: the ending's message and code, then the platform's redirect or MTurk hand-in.
import { $, show } from "./page.js";

const REDIRECT_DELAY_MS = 5000;

/** The stored ending: its message and code, then the platform's redirect or MTurk hand-in form. */
export function showDone(app, state) {
  if (state.progress) app.updateProgress(state.progress);
  const step = state.step || {};
  const finished = app.rules.finished_outcomes.includes(step.outcome);
  $("done-heading").textContent = finished ? "Thank you!" : "The study has ended";
  $("done-message").textContent = step.message || (finished ? "You have finished the study." : "");
  $("completion-code").textContent = step.completion_code ?? "";
  $("code-block").hidden = !step.completion_code;
  show("done");
  app.telemetry.flush();
  if (step.mturk_submit) {
    showMturkForm(step.mturk_submit);
  } else if (step.redirect_url) {
    $("redirect-link").href = step.redirect_url;
    $("redirect-block").hidden = false;
    setTimeout(() => location.assign(step.redirect_url), REDIRECT_DELAY_MS);
  }
}

/** MTurk's ExternalQuestion hand-in: POST assignmentId (and the ending) to turkSubmitTo. */
function showMturkForm({ action, fields }) {
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
