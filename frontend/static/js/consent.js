// The consent screen: the study's consent sections, agree or decline.
import { clientInfo } from "./device.js";
import { $, pressRetries, setProse, show } from "./page.js";

/** Show the consent; resolves with the next state once agreeing or declining is stored. */
export function showConsent(app, step) {
  showConsentForm($("consent-text"), step);
  show("consent");
  const check = $("consent-check");
  const button = $("consent-agree");
  check.checked = false;
  button.disabled = true;
  check.onchange = () => { button.disabled = !check.checked; };
  const decline = $("consent-decline");
  decline.disabled = false;
  return new Promise((resolve, reject) => {
    button.onclick = () => {
      button.disabled = true;
      decline.disabled = true;
      app.api.consent(clientInfo(app.rules.user_agent_max_chars), pressRetries($("consent-status"))).then(resolve, reject);
    };
    decline.onclick = () => {
      button.disabled = true;
      decline.disabled = true;
      app.api.decline(pressRetries($("consent-status"))).then(resolve, reject);
    };
  });
}

/** The consent page: its typed sections (app/study/consent.py), each a heading and prose
 * with e-mail addresses as links, or a study's older free text. */
function showConsentForm(element, step) {
  const sections = step?.sections ?? [];
  if (!sections.length) {
    setProse(element, step?.text ?? step?.consent_text ?? "");
    return;
  }
  element.replaceChildren(...sections.flatMap(({ heading, text }) => {
    const title = document.createElement("h3");
    title.textContent = heading;
    const body = document.createElement("div");
    setProse(body, text);
    body.querySelectorAll("p").forEach(linkEmails);
    return [title, ...body.children];
  }));
}

/** Turn the e-mail addresses in a paragraph's text into mailto links. */
function linkEmails(paragraph) {
  const parts = paragraph.textContent.split(/([^\s@,;()]+@[^\s@,;()]+\.[A-Za-z]{2,})/);
  if (parts.length === 1) return;
  paragraph.replaceChildren(...parts.map((part, i) => {
    if (i % 2 === 0) return document.createTextNode(part);
    const link = document.createElement("a");
    link.href = `mailto:${part}`;
    link.textContent = part;
    return link;
  }));
}
