// What comes before the trials: the instructions and their demo, a part's world, its practice's end.
import { InstructionsDemo } from "./demo.js";
import { $, pressRetries, setProse, show } from "./page.js";
import { drawBackground, label, prepareCanvas } from "./scene.js";
import { DEMO } from "./words.js";

/** The instructions and their animated demo; resolves with the next state once read. */
export function showInstructions(app, step) {
  setProse($("instructions-text"), step?.text ?? step?.instructions_text ?? "");
  show("instructions");
  const player = new InstructionsDemo($("demo-canvas"), DEMO, {
    rules: app.rules.predictions,
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
      app.api.instructionsDone(pressRetries($("instructions-status"))).then(resolve, reject);
    };
  });
}

/** A part's first screen: which part, its world explained and drawn, what the part holds. */
export function showWorld(app, state) {
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
  return continueFrom(app.api, state.phase, button);
}

/** After a part's practice: the trials that count come next. */
export function showPracticeOver(app, state) {
  const step = state.step;
  $("practice-over-part").textContent = `Part ${step.part} of ${step.parts}: ${step.title}`;
  $("practice-over-text").textContent = `That was the practice. The next ${step.trials} trials count; `
    + `they are numbered 1 to ${step.trials}. After each one you can take a short break.`;
  show("practice-over");
  return continueFrom(app.api, state.phase, $("practice-over-done"));
}

/** Resolve with the next state once `button` is pressed and the server has moved on (its
 * screen's status line says so while it cannot be reached). */
function continueFrom(api, phase, button) {
  button.disabled = false;
  button.focus();
  const status = button.closest("section").querySelector(".press-status");
  status.textContent = "";
  return new Promise((resolve, reject) => {
    button.onclick = () => {
      button.disabled = true;
      api.continueFrom(phase, pressRetries(status)).then(resolve, reject);
    };
  });
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
