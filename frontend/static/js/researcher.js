// Researcher dashboard: token in sessionStorage, sessions, live plots, replays, CSV export.
import { ApiError, ResearcherApi, requestJson } from "./api.js";
import { ParticipantsTable, renderErrors, renderFields, renderVerdicts, renderVersions } from "./dashboard.js";
import { ReplayView } from "./replay.js";

const TOKEN_KEY = "tomstudy.researcher.token";
const REFRESH_MS = 10000;
const $ = (id) => document.getElementById(id);

function title(key) {
  return key.replace(/_/g, " ");
}

function formatValue(value) {
  if (typeof value === "number") return Number.isInteger(value) ? String(value) : value.toFixed(3);
  if (value === null || value === undefined) return "–";
  if (typeof value === "object") return JSON.stringify(value);
  return String(value);
}

/** A table for a list of flat objects. */
function rowsTable(rows) {
  const wrap = document.createElement("div");
  wrap.className = "table-wrap";
  const table = document.createElement("table");
  wrap.append(table);
  table.className = "summary";
  const columns = [...new Set(rows.flatMap((row) => Object.keys(row)))];
  const head = table.createTHead().insertRow();
  for (const column of columns) {
    const th = document.createElement("th");
    th.textContent = title(column);
    head.append(th);
  }
  const body = table.createTBody();
  for (const row of rows) {
    const tr = body.insertRow();
    for (const column of columns) tr.insertCell().textContent = formatValue(row[column]);
  }
  return wrap;
}

function isFlatObject(value) {
  return Boolean(value) && typeof value === "object" && !Array.isArray(value)
    && Object.keys(value).length > 0
    && Object.values(value).every((v) => v === null || typeof v !== "object");
}

function note(text) {
  return Object.assign(document.createElement("p"), { textContent: text });
}

/** An object whose values are all flat objects, e.g. {highway: {ours: .., vae: ..}}. */
function isTableOfRecords(value) {
  const rows = Object.values(value ?? {});
  return !Array.isArray(value) && rows.length > 0 && rows.every(isFlatObject);
}

/** Render any JSON summary: scalars as a key/value table, lists of objects as tables, objects nested. */
function renderSummary(data, depth = 3) {
  const fragment = document.createDocumentFragment();
  const scalars = Object.entries(data).filter(([, v]) => v === null || typeof v !== "object");
  if (scalars.length) fragment.append(rowsTable(scalars.map(([key, value]) => ({ item: title(key), value }))));
  for (const [key, value] of Object.entries(data)) {
    if (value === null || typeof value !== "object") continue;
    const heading = document.createElement(`h${Math.min(depth, 5)}`);
    heading.textContent = title(key);
    fragment.append(heading);
    if (isTableOfRecords(value)) {
      fragment.append(rowsTable(Object.entries(value).map(([name, row]) => ({ [key]: name, ...row }))));
    } else if (Array.isArray(value)) {
      if (!value.length) fragment.append(note("none yet"));
      else if (value.every((v) => v && typeof v === "object" && !Array.isArray(v))) fragment.append(rowsTable(value));
      else fragment.append(note(value.map(formatValue).join(", ")));
    } else if (!Object.keys(value).length) {
      fragment.append(note("none yet"));
    } else {
      fragment.append(renderSummary(value, depth + 1));
    }
  }
  return fragment;
}

/** The headline: usable participants (kept by the study's exclusion rules) against the
 * target, with a bar, then how many finished and why the others are excluded. */
function progressLine(progress) {
  const line = document.createElement("p");
  if (!progress?.target_sample_size) return line;
  const usable = progress.usable ?? progress.completed;
  const bar = Object.assign(document.createElement("progress"), {
    max: progress.target_sample_size, value: Math.min(usable, progress.target_sample_size),
  });
  line.append(`${usable} usable of ${progress.target_sample_size} `, bar, ` ${usableDetail(progress, usable)}`);
  return line;
}

/** The advertised time and pay beside the finished sessions' median and what it really pays
 * per hour (app/researcher/pay.py), and a warning when the median overruns the advertised time. */
function timeAndPayLines(time) {
  if (!time) return [];
  const line = document.createElement("p");
  line.id = "time-and-pay";
  const pay = time.pay ? `, pay ${time.pay} (${time.hourly})` : "";
  const median = time.median_min === null
    ? "no finished sessions yet"
    : `median of ${time.sessions} finished ${time.who}: ${time.median_min} min`
      + (time.effective_hourly ? `, effectively ${time.effective_hourly} per hour` : "");
  line.textContent = `Advertised ${time.advertised_min} min${pay} (estimate: median `
    + `${time.estimate_min} min, slow ${time.slow_estimate_min} min); ${median}.`;
  if (!time.overrun) return [line];
  const flag = document.createElement("p");
  flag.className = "warning";
  flag.id = "time-overrun";
  flag.setAttribute("role", "alert");
  flag.textContent = time.flag;
  return [line, flag];
}

/** "25 finished, 7 excluded: failed attention check 4, too fast 3" (nothing excluded: "25 finished"). */
function usableDetail(progress, usable) {
  const excluded = progress.completed - usable;
  const rules = Object.entries(progress.excluded_by_rule ?? {}).map(([rule, n]) => `${title(rule)} ${n}`);
  return `${progress.completed} finished` + (excluded > 0 ? `, ${excluded} excluded${rules.length ? `: ${rules.join(", ")}` : ""}` : "");
}

/** Each ending's completion code with what to do with it on Prolific. */
function codesTable(codes) {
  return rowsTable((codes ?? []).map((c) => ({
    ending: title(c.ending), completion_code: c.completion_code || "(none)", "on Prolific": c.prolific_action,
  })));
}

/** The withdrawal audit: when, how, which kind of id and what was deleted (no id in it). */
function auditTable(lines) {
  if (!lines.length) return note("No withdrawals.");
  return rowsTable(lines.map((line) => ({
    audit_line: line.id, withdrawn_at: new Date(line.withdrawn_at).toLocaleString(), via: line.via,
    by: title(line.id_kind), sessions: line.row_counts.participant ?? 0,
    rows_deleted: Object.values(line.row_counts).reduce((a, b) => a + b, 0),
    salted_id_hash: `${line.id_sha256.slice(0, 16)}…`,
  })));
}

function withdrawalText(line) {
  const rows = Object.values(line.row_counts).reduce((a, b) => a + b, 0);
  const archives = (line.archives ?? []).map((a) => a.path);
  const reissue = archives.length
    ? ` Re-issue without them the archive(s) that hold them: ${archives.join(", ")}.` : "";
  return `Withdrawn: ${line.row_counts.participant} session(s) and ${rows} rows deleted `
    + `(audit line ${line.id}, ${new Date(line.withdrawn_at).toLocaleString()}). ${line.storage}.`
    + reissue;
}

/** GET a researcher route with the bearer token; `params` become the query string. */
function researcherGet(api, path, params) {
  return requestJson("GET", `/api/researcher/${path}?${new URLSearchParams(params)}`, undefined, api.auth());
}

function exclusionsText(counts) {
  if (!counts?.participants_total) return "No answers yet.";
  const rules = Object.entries(counts).filter(([k, v]) => k.startsWith("excluded_") && v).map(([k, v]) => `${title(k.slice(9))} ${v}`);
  return `${counts.participants_kept} of ${counts.participants_total} participants kept`
    + `${rules.length ? ` (excluded: ${rules.join(", ")})` : ""}; ${counts.too_fast_trials_dropped} too-fast trials dropped. `
    + "Dots: each participant's mean; black: mean of those means with its 95% t interval.";
}

class Dashboard {
  constructor() {
    this.api = null;
    this.timer = null;
    this.fieldsKey = "";
    this.table = new ParticipantsTable($("participants"), (row) => this.replay.openSession(row).catch((e) => this.report(e)));
    this.replay = new ReplayView(
      (publicId) => researcherGet(this.api, `participants/${encodeURIComponent(publicId)}/trials`, { study_id: this.studyId() }),
      (publicId, trialId) => researcherGet(this.api, `participants/${encodeURIComponent(publicId)}/trials/${encodeURIComponent(trialId)}`, { study_id: this.studyId() }),
    );
  }

  report(error) {
    $("dashboard-message").textContent = `Could not load: ${error.message}`;
  }

  start() {
    $("token-form").addEventListener("submit", (event) => {
      event.preventDefault();
      this.login($("token-input").value.trim());
    });
    $("refresh").onclick = () => this.refresh();
    $("download").onclick = () => this.download();
    $("download-codebook").onclick = () => this.download(true);
    $("logout").onclick = () => this.logout();
    $("rules-select").onchange = () => this.refresh();
    $("show-external-ids").onchange = () => this.refresh();
    $("summary-box").ontoggle = () => this.refresh();
    $("withdraw-form").addEventListener("submit", (event) => {
      event.preventDefault();
      this.askToWithdraw();
    });
    $("withdraw-dialog").addEventListener("close", () => {
      if ($("withdraw-dialog").returnValue === "confirm") this.withdraw();
    });
    const saved = sessionStorage.getItem(TOKEN_KEY);
    if (saved) this.login(saved);
  }

  studyId() {
    return $("study-input").value.trim();
  }

  async login(token) {
    this.api = new ResearcherApi(token);
    let data;
    try {
      data = await this.load();
    } catch (error) {
      $("login-message").textContent = error instanceof ApiError && [401, 403].includes(error.status)
        ? "That token is not valid." : `Could not load the summary: ${error.message}`;
      sessionStorage.removeItem(TOKEN_KEY);
      return;
    }
    sessionStorage.setItem(TOKEN_KEY, token);
    $("login-message").textContent = "";
    $("login").hidden = true;
    $("dashboard").hidden = false; // before drawing: canvases take their parent's width
    this.render(data);
    clearInterval(this.timer);
    this.timer = setInterval(() => this.refresh(), REFRESH_MS);
  }

  logout() {
    sessionStorage.removeItem(TOKEN_KEY);
    clearInterval(this.timer);
    this.api = null;
    $("dashboard").hidden = true;
    $("login").hidden = false;
    $("token-input").value = "";
  }

  /**
   * The dashboard's data, and the raw summary only while its box is open: both read every
   * prediction row, so a refresh reads them once unless the researcher asks for the JSON.
   */
  load() {
    const summary = $("summary-box").open ? this.api.summary(this.studyId()) : null;
    return Promise.all([summary, this.dashboard()]);
  }

  render([summary, board]) {
    $("progress-line").replaceChildren(progressLine(board.progress), ...timeAndPayLines(board.time_and_pay));
    $("completion-codes").replaceChildren(codesTable(board.completion_codes));
    this.showAudit();
    if (summary) $("summary").replaceChildren(renderSummary(summary));
    this.show(board);
    $("dashboard-message").textContent = `Updated ${new Date().toLocaleTimeString()}.`;
  }

  async refresh() {
    try {
      this.render(await this.load());
    } catch (error) {
      $("dashboard-message").textContent = `Could not refresh: ${error.message}`;
    }
  }

  dashboard() {
    return researcherGet(this.api, "dashboard", {
      study_id: this.studyId(), rules: $("rules-select").value, external_ids: $("show-external-ids").checked,
    });
  }

  show(board) {
    renderVersions($("versions"), board.versions);
    this.table.show(board.participants);
    const { alignment } = board;
    $("exclusions").textContent = exclusionsText(alignment.exclusions);
    renderVerdicts($("verdicts"), alignment.verdicts);
    renderErrors($("error-plots"), alignment.worlds, alignment.predictors, alignment.style);
    const key = JSON.stringify(alignment.fields); // redraw the canvases only when they change
    if (key !== this.fieldsKey) renderFields($("fields"), alignment.fields);
    this.fieldsKey = key;
  }

  /** Open the confirmation dialog for the id in the withdrawal form. */
  askToWithdraw() {
    const kind = $("withdraw-kind").value;
    const id = $("withdraw-id").value.trim();
    if (!id) return;
    this.pendingWithdrawal = { kind, id, studyId: this.studyId() };
    const who = kind === "external_id" ? `platform id ${id}` : `session ${id}`;
    $("withdraw-dialog-text").textContent = `Every session of ${who} in study `
      + `${this.pendingWithdrawal.studyId}, with all its answers, survey and telemetry, is deleted `
      + "now and cannot be restored. The audit keeps only when, how and a salted hash of the id. "
      + "Pay or approve this person first: the participants sheet loses the row.";
    $("withdraw-dialog").returnValue = "";
    $("withdraw-dialog").showModal();
  }

  async withdraw() {
    const { kind, id, studyId } = this.pendingWithdrawal;
    this.pendingWithdrawal = null;
    const message = $("withdraw-message");
    message.className = "message";
    message.textContent = "Withdrawing…";
    try {
      const line = await this.api.withdraw(studyId, kind, id);
      message.className = "message ok";
      message.textContent = withdrawalText(line);
      $("withdraw-id").value = "";
      await this.refresh();
    } catch (error) {
      message.className = "message error";
      message.textContent = `Not withdrawn: ${error.message}`;
    }
  }

  async showAudit() {
    try {
      $("withdraw-audit").replaceChildren(auditTable(await this.api.withdrawals(this.studyId())));
    } catch (error) {
      $("withdraw-audit").replaceChildren(note(`Could not load the audit: ${error.message}`));
    }
  }

  /** Download the chosen export's CSV, or (`codebook`) its datapackage.json, named as the
   * package's resource path expects: <study>_<what>.csv beside <study>_<what>.datapackage.json. */
  async download(codebook = false) {
    $("dashboard-message").textContent = codebook ? "Preparing the codebook…" : "Preparing the export…";
    try {
      const what = $("export-what").value;
      const base = `${this.studyId() || "study"}_${what}`;
      const blob = codebook ? await this.api.exportPackage(this.studyId(), what) : await this.api.exportCsv(this.studyId(), what);
      saveBlob(blob, codebook ? `${base}.datapackage.json` : `${base}.csv`);
      $("dashboard-message").textContent = `Downloaded ${(blob.size / 1024).toFixed(1)} kB.`;
    } catch (error) {
      $("dashboard-message").textContent = `${codebook ? "Codebook" : "Export"} failed: ${error.message}`;
    }
  }
}

function saveBlob(blob, name) {
  const url = URL.createObjectURL(blob);
  const link = Object.assign(document.createElement("a"), { href: url, download: name });
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
}

new Dashboard().start();
