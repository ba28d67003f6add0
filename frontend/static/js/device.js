// Whether this device can run the study: a check per screen-out reason and the screen saying why.
import { prefersReducedMotion } from "./player.js";
import { $, STUDY_SCREENS, show, shownScreen } from "./page.js";

/**
 * One check per reason the server takes for a screen-out (app/server/schemas.py
 * `ScreenOutReason`; the page lists them in its rules): given the smallest window the
 * server's prediction view is made for, why this device cannot run the study, or null.
 */
export const DEVICE_CHECKS = {
  touch_only: () => (matchMedia("(any-pointer: coarse)").matches && !matchMedia("(any-pointer: fine)").matches
    ? "This study needs a mouse or touchpad: touch-only devices are not supported." : null),
  window_too_small: (min) => (innerWidth < min.width || innerHeight < min.height
    ? `Your browser window is ${innerWidth} × ${innerHeight} pixels; the study needs at least ${min.width} × ${min.height}.`
    : null),
};

/** Why this device cannot run the study ({code, text}: code as POST /screen-out takes it), or null. */
function unsupportedReason(checks, minWindow) {
  for (const [code, check] of checks) {
    const text = check(minWindow);
    if (text) return { code, text };
  }
  return null;
}

/** What the consent records of this device (POST /consent's client info). */
export function clientInfo(userAgentMaxChars) {
  return {
    screen_w: innerWidth,
    screen_h: innerHeight,
    touch_only: false,
    reduced_motion: prefersReducedMotion(),
    user_agent: navigator.userAgent.slice(0, userAgentMaxChars),
  };
}

/**
 * Resolves with `state` once the window is large enough and has a fine pointer. Before
 * any trial the participant may instead end the study here: the server stores the
 * screened-out ending and the promise resolves with the done state.
 */
export function waitForDevice(app, state) {
  const canEnd = app.rules.screen_out_phases.includes(state.phase);
  return new Promise((resolve, reject) => {
    const check = () => {
      const reason = unsupportedReason(app.deviceChecks, app.rules.min_window);
      if (!reason) {
        removeEventListener("resize", check);
        resolve(state);
        return;
      }
      $("unsupported-reason").textContent = reason.text;
      $("screen-out-block").hidden = !canEnd;
      $("screen-out").onclick = () => {
        removeEventListener("resize", check);
        $("screen-out").disabled = true;
        app.api.screenOut(reason.code).then(resolve, reject);
      };
      show("unsupported");
    };
    addEventListener("resize", check);
    check();
  });
}

/**
 * Once the study runs, a window made smaller than the display check allows covers the
 * screen with the reason until it is large enough again, then the same screen comes back
 * as it was (this listener runs before the canvases' own, which then redraw at full size).
 */
export function coverWhileTooSmall(app) {
  const check = app.deviceChecks.get("window_too_small");
  if (!check) return;
  let covered = null;
  addEventListener("resize", () => {
    const text = check(app.rules.min_window);
    if (text) {
      covered ??= shownScreen();
      if (!STUDY_SCREENS.includes(covered)) {
        covered = null;
        return;
      }
      coverWith(text);
    } else if (covered) {
      if (!$("screen-unsupported").hidden) show(covered);
      covered = null;
    }
  });
}

/** The screen that asks for a larger window, saying `text` of why. */
function coverWith(text) {
  $("unsupported-title").textContent = "Please make the window larger";
  $("unsupported-help").textContent = "Your answers so far are saved. When the window is large enough again, the study continues where you were.";
  $("unsupported-reason").textContent = text;
  $("screen-out-block").hidden = true;
  show("unsupported");
}
