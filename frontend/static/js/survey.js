// The survey screen: one input per kind of question, the answers read back from the form and sent.
import { ApiError } from "./api.js";
import { $, pressRetries, show } from "./page.js";

/**
 * One input per kind of survey question the server has (app/study/config.py
 * `SurveyQuestion.kind`; the page lists them in its rules): its element, and the answer
 * from the form's value.
 */
export const QUESTION_INPUTS = {
  likert: {
    element: (question) => choiceRow(question, "likert", Array.from(
      { length: question.scale_max - question.scale_min + 1 }, (_, i) => String(question.scale_min + i))),
    answer: Number,
  },
  text: { element: textArea, answer: String },
  choice: { element: (question) => choiceRow(question, "choices", question.options), answer: String },
};

/** Show the survey; resolves with the next state once the answers are stored. */
export function showSurvey(app, step) {
  const questions = step?.questions ?? [];
  const container = $("survey-questions");
  container.replaceChildren(...questions.map((question) => questionElement(question, app.questionInputs)));
  show("survey");
  const form = $("survey-form");
  return new Promise((resolve, reject) => {
    form.onsubmit = (event) => {
      event.preventDefault();
      const { answers, missing } = collectAnswers(form, questions, app.questionInputs);
      if (missing.length) {
        $("survey-message").textContent = `Please answer: ${missing.join("; ")}`;
        return;
      }
      $("survey-message").textContent = "";
      form.querySelector("button[type=submit]").disabled = true;
      // the server refuses events once the session is done: send what is queued first
      const retries = pressRetries($("survey-message"));
      app.telemetry.flush().then(() => app.api.survey(answers, retries)).then(resolve, (error) => {
        form.querySelector("button[type=submit]").disabled = false;
        if (error instanceof ApiError && error.status < 500) $("survey-message").textContent = error.detail;
        else reject(error);
      });
    };
  });
}

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
