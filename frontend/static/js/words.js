// What the pages call the two agents, the scripts' texts that name them and the instructions'
// demo: the study's (app/study/words.py), which every page that draws a scene carries as
// #study-words. Shown with textContent only: a config's words are never markup.
const PAGE = JSON.parse(document.getElementById("study-words").textContent);

/** The study's words: agent, other, agent_key, other_key, agent_look, other_look. */
export const WORDS = PAGE.words;

/** Which illustration the instructions show (app/study/words.py DemoName). */
export const DEMO = PAGE.demo;

/** The study's text `name` with each {placeholder} filled from `values`. */
export function say(name, values = {}) {
  const text = PAGE.texts[name];
  if (text === undefined) throw new Error(`no text ${name} in #study-words`);
  return text.replace(/\{(\w+)\}/g, (whole, key) => (Object.hasOwn(values, key) ? String(values[key]) : whole));
}
