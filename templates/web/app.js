// loceval browser page: upload recordings, start evaluations, watch them, fetch the results.
// Plain ES2020; one library, the vendored tus-js-client (window.tus) for resumable uploads.
// Every text that comes from the server is set with textContent.
"use strict";

(() => {
  const KEY_STORAGE = "loceval.apiKey";
  const API = "api/v1";
  const POLL_MS = 1000;
  const HISTORY_POLL_MS = 5000;
  const PARALLEL_UPLOADS = 2;
  const UNAUTHORIZED =
    "The server did not accept the API key (401 Unauthorized). " +
    "Paste a valid key for your project in the box at the top of the page.";
  // The files an evaluation can make, in the server's order: rendered into the page by the
  // server from its list of artifacts, never copied here by hand.
  const ALL_ARTIFACTS = JSON.parse(document.body.dataset.artifacts || "[]");
  const OPENED_IN_TAB = new Set(["report.html", "report.pdf"]);
  const NONE = "— none —"; // the empty choice of an optional dataset field (device, building)
  // The server renders whether it can write PDFs (always with its own templates, which Typst
  // typesets; HTML templates of an administrator's own need WeasyPrint and pango): without,
  // the page asks for no report.pdf and its schedules for summary.html only.
  const PDF_REPORTS = document.body.dataset.pdfReports !== "no";
  // The API's options document (GET /api/v1/options), rendered into the page by the server:
  // key, kind, default, bounds, choices and help of every option, from the one table the
  // API's schema and the CLI's flags are made from. The form's fields take their bounds,
  // choices and help from it, and an option no field of the page holds gets one of its own.
  // The readers' formats and what each file holds, from the server (<body data-formats>).
  const READ_FORMATS = JSON.parse(document.body.dataset.formats || "[]");
  const OPTION_DOCS = new Map(JSON.parse(document.body.dataset.options || "[]").map((o) => [o.key, o]));
  const FORM_GROUPS = new Set(["evaluation", "reading", "export", "map", "baseline"]); // not ranging's

  const state = {
    key: null,
    datasets: [],
    sources: new Map(), // option value -> {dataset, source, label}
    watchId: null,
    watchTimer: null,
    watchSeq: 0,
    historyTimer: null,
    uploadQueue: [],
    uploadsRunning: 0,
    datasetsTimer: null,
    history: null,
    keyVerified: false, // the server has accepted the key at least once
    schedules: [],
    scheduleRuns: new Map(), // schedule id -> its newest run (or null)
    runTimers: new Map(), // schedule id -> timer of a run being watched
  };

  // --- small helpers ---------------------------------------------------------------------

  const $ = (id) => document.getElementById(id);

  /** Create an element; text children become text nodes (never parsed as HTML). */
  function el(tag, props = {}, ...children) {
    const node = document.createElement(tag);
    for (const [name, value] of Object.entries(props)) {
      if (value === undefined || value === null || value === false) continue;
      if (name === "className") node.className = value;
      else if (name === "text") node.textContent = String(value);
      else if (name === "dataset") Object.assign(node.dataset, value);
      else if (name.startsWith("on")) node.addEventListener(name.slice(2), value);
      else if (value === true) node.setAttribute(name, "");
      else node.setAttribute(name, String(value));
    }
    for (const child of children.flat()) {
      if (child === undefined || child === null || child === false) continue;
      node.append(child instanceof Node ? child : document.createTextNode(String(child)));
    }
    return node;
  }

  function formatBytes(n) {
    if (typeof n !== "number" || !Number.isFinite(n)) return "—";
    if (n < 1000) return `${n} B`;
    const units = ["kB", "MB", "GB", "TB"];
    let value = n;
    let i = -1;
    do {
      value /= 1000;
      i += 1;
    } while (value >= 1000 && i < units.length - 1);
    return `${value >= 100 ? value.toFixed(0) : value.toFixed(1)} ${units[i]}`;
  }

  /** A length in metres as the report prints it: three decimals. */
  // The one rule for lengths, as the viewer, the reports and the command line print them
  // (loceval/core/lengths.py, docs/files.md "Units and digits"): a group of lengths shown together
  // (a table) reads in millimetres to a tenth when every value is below 0.1 m, else in
  // metres to the millimetre.
  function lengthUnit(values) {
    const finite = values.filter((v) => typeof v === "number" && Number.isFinite(v)).map(Math.abs);
    return finite.length && Math.max(...finite) < 0.1
      ? { symbol: "mm", perMetre: 1000, decimals: 1 }
      : { symbol: "m", perMetre: 1, decimals: 3 };
  }

  function formatMetres(m, unit = lengthUnit([m])) {
    return typeof m === "number" && Number.isFinite(m) ? `${(m * unit.perMetre).toFixed(unit.decimals)} ${unit.symbol}` : "—";
  }

  function formatSeconds(s) {
    if (typeof s !== "number" || !Number.isFinite(s)) return "";
    return s >= 100 ? `${s.toFixed(0)} s` : `${s.toFixed(1)} s`;
  }

  function formatTime(iso) {
    if (!iso) return "—";
    const date = new Date(iso);
    if (Number.isNaN(date.getTime())) return String(iso);
    return date.toLocaleString(undefined, {
      year: "numeric", month: "short", day: "numeric",
      hour: "2-digit", minute: "2-digit", second: "2-digit",
    });
  }

  function capitalize(text) {
    return text ? text[0].toUpperCase() + text.slice(1) : text;
  }

  function plural(n, one, many) {
    return `${n} ${n === 1 ? one : many}`;
  }

  function setHidden(node, hidden) {
    node.hidden = Boolean(hidden);
  }

  // --- banner and key ----------------------------------------------------------------------

  function showBanner(text, kind = "error") {
    $("banner-text").textContent = text;
    $("banner").className = `banner banner-${kind}`;
    setHidden($("banner"), false);
  }

  function hideBanner() {
    setHidden($("banner"), true);
  }

  function readStoredKey() {
    try {
      return window.localStorage.getItem(KEY_STORAGE);
    } catch {
      return null;
    }
  }

  function storeKey(key) {
    try {
      if (key) window.localStorage.setItem(KEY_STORAGE, key);
      else window.localStorage.removeItem(KEY_STORAGE);
    } catch {
      // Private windows may refuse storage: the key then lives until the page is closed.
    }
  }

  function renderKeyState({ askAgain = false } = {}) {
    const hasKey = Boolean(state.key);
    setHidden($("key-form"), hasKey && !askAgain);
    setHidden($("key-status"), !hasKey);
    $("key-hint").textContent = hasKey ? `…${state.key.slice(-4)}` : "";
    setHidden($("welcome"), hasKey);
    setHidden($("app"), !hasKey);
  }

  function onUnauthorized() {
    if (!state.keyVerified) {
      // A key that never worked is not kept: the next visit asks again.
      state.key = null;
      storeKey(null);
    }
    stopWatching();
    stopHistoryPolling();
    renderKeyState({ askAgain: true });
    showBanner(UNAUTHORIZED, "error");
    $("key-input").focus();
  }

  function useKey(key) {
    state.key = key;
    state.keyVerified = false;
    storeKey(key);
    $("key-input").value = "";
    hideBanner();
    renderKeyState();
    loadAll();
  }

  function forgetKey() {
    state.key = null;
    state.keyVerified = false;
    storeKey(null);
    stopWatching();
    stopHistoryPolling();
    state.datasets = [];
    state.history = null;
    stopRunWatching();
    state.schedules = [];
    state.scheduleRuns.clear();
    $("schedules-body").replaceChildren();
    state.sources.clear();
    renderSourceSelects();
    renderRadioSelects();
    $("datasets-body").replaceChildren();
    $("history-body").replaceChildren();
    $("upload-list").replaceChildren();
    updateClearButton();
    setHidden($("current-card"), true);
    hideBanner();
    renderKeyState();
    $("key-input").focus();
  }

  // --- API ---------------------------------------------------------------------------------

  class ApiError extends Error {
    constructor(status, message, fields = []) {
      super(message);
      this.status = status;
      this.fields = fields; // the option keys the problem is about (max_dt_s, device.to_link)
    }
  }

  // --- the page's names of the options -------------------------------------------------------
  // The API names an option options.max_dt_s; the page names its field (“Nearest: max Δt”).
  // Each field carries data-option (the key) and data-label (its name on the page).

  function optionField(key) {
    for (const node of document.querySelectorAll("[data-option]")) {
      if (node.dataset.option === key) return node;
    }
    return null;
  }

  /** The page's field of an option path (``device.to_link``, ``thresholds_m.1``), and the rest. */
  function fieldOf(path) {
    const parts = path.split(".");
    for (let n = parts.length; n > 0; n -= 1) {
      const node = optionField(parts.slice(0, n).join("."));
      if (node) return { node, rest: parts.slice(n) };
    }
    return { node: null, rest: parts };
  }

  const OPTION_PATH = /(?:\bbody\.)?(?:\btemplate\.)?\boptions\.([A-Za-z_]+(?:\.[A-Za-z_0-9]+)*)/g;

  /** Replace every ``options.KEY`` in a server message by the name of the page's field. */
  function nameFields(text) {
    return String(text).replace(OPTION_PATH, (match, path) => {
      const { node, rest } = fieldOf(path);
      if (!node) return match;
      const index = rest.length && /^\d+$/.test(rest[0]) ? ` (value ${Number(rest[0]) + 1})` : "";
      return `“${node.dataset.label}”${index}`;
    });
  }

  /** The option keys a problem document is about: its ``option`` member and its errors' loc. */
  function problemFields(bodyText) {
    let body = null;
    try {
      body = bodyText ? JSON.parse(bodyText) : null;
    } catch {
      return [];
    }
    if (!body || typeof body !== "object") return [];
    const keys = [];
    if (typeof body.option === "string") keys.push(body.option.replace(/^options\./, ""));
    for (const e of Array.isArray(body.errors) ? body.errors : []) {
      const loc = e && Array.isArray(e.loc) ? e.loc.map(String) : [];
      const at = loc.indexOf("options");
      if (at >= 0 && at + 1 < loc.length) keys.push(loc.slice(at + 1).join("."));
    }
    return keys;
  }

  function clearInvalid(form) {
    for (const node of form.querySelectorAll(".invalid")) node.classList.remove("invalid");
  }

  /** Mark the fields a problem is about and open the section that holds the first one. */
  function markInvalid(keys) {
    let first = null;
    for (const key of keys) {
      const { node } = fieldOf(key);
      if (!node) continue;
      node.classList.add("invalid");
      first = first || node;
    }
    if (!first) return;
    const details = first.closest("details");
    if (details) details.open = true;
    const input = first.querySelector("input, select, textarea");
    if (input) input.focus();
  }

  /** Plain words for a failed response, from its problem+json body when there is one. */
  function problemText(status, statusText, bodyText) {
    let body = null;
    try {
      body = bodyText ? JSON.parse(bodyText) : null;
    } catch {
      body = null;
    }
    if (body && typeof body === "object") {
      const { detail, title } = body;
      if (typeof detail === "string" && detail) return nameFields(detail);
      if (Array.isArray(detail) && detail.length) {
        return detail
          .map((d) => {
            if (!d || typeof d !== "object") return String(d);
            const where = Array.isArray(d.loc) ? d.loc.filter((p) => p !== "body").join(".") : "";
            return nameFields(where ? `${where}: ${d.msg}` : String(d.msg));
          })
          .join("; ");
      }
      if (Array.isArray(body.errors) && body.errors.length) {
        return body.errors.map((e) => (e && e.msg) || String(e)).join("; ");
      }
      if (typeof title === "string" && title) return title;
    }
    if (status === 413) return "The file is larger than the server accepts.";
    if (status >= 500) return `The server failed (${status} ${statusText}). Try again, or tell whoever runs the server.`;
    return `The server answered ${status} ${statusText}.`.replace(/ \.$/, ".");
  }

  /**
   * What the page says when the server refuses an upload. An unreadable file's problem ends
   * in advice for the command line (a format prefix such as tum:FILE, a column mapping),
   * which the page has no field for: the page keeps what is wrong and says what it reads.
   */
  function uploadProblemText(status, statusText, bodyText) {
    let body = null;
    try {
      body = JSON.parse(bodyText);
    } catch {
      body = null;
    }
    if (!body || body.type !== "input.unreadable" || typeof body.detail !== "string") {
      return problemText(status, statusText, bodyText);
    }
    const cli = /;[^;]*(prefix|e\.g\. [a-z]+:|map it)/;
    const what = body.detail.search(cli) > 0 ? body.detail.slice(0, body.detail.search(cli)) : body.detail.replace(/\.$/, "");
    const formats = READ_FORMATS.map((f) => f.shape).join("; ");
    return `${what}. The page reads these formats: ${formats}. Save or export the recording in one of them and upload it again.`;
  }

  function authHeaders() {
    return { Authorization: `Bearer ${state.key}` };
  }

  async function apiFetch(url, options = {}) {
    let response;
    try {
      response = await fetch(url, {
        ...options,
        cache: "no-store",
        headers: { ...authHeaders(), ...(options.headers || {}) },
      });
    } catch {
      throw new ApiError(0, "Cannot reach the server. Check that it is running and that this computer is on its network.");
    }
    if (response.status === 401) {
      onUnauthorized();
      throw new ApiError(401, UNAUTHORIZED);
    }
    state.keyVerified = true; // anything but 401 means the key was accepted
    if (!response.ok) {
      const text = await response.text().catch(() => "");
      throw new ApiError(
        response.status, problemText(response.status, response.statusText, text), problemFields(text));
    }
    return response;
  }

  async function api(path, { method = "GET", json } = {}) {
    const options = { method, headers: { Accept: "application/json" } };
    if (json !== undefined) {
      options.headers["Content-Type"] = "application/json";
      options.body = JSON.stringify(json);
    }
    const response = await apiFetch(`${API}${path}`, options);
    if (response.status === 204) return null;
    return response.json();
  }

  function reportError(err, where) {
    if (err instanceof ApiError && err.status === 401) return; // the banner says it already
    const text = err instanceof Error ? err.message : String(err);
    if (where) where.textContent = text;
    else showBanner(text, "error");
  }

  async function loadAll() {
    await loadDatasets(); // first, so the history can name the datasets
    await loadHistory();
    await loadSchedules();
  }

  // --- uploads -----------------------------------------------------------------------------

  function enqueueUploads(files) {
    const tags = $("tags-input").value.trim();
    for (const file of files) {
      const item = uploadItem(file);
      $("upload-list").prepend(item.node);
      state.uploadQueue.push({ file, tags, item });
    }
    pumpUploads();
  }

  function pumpUploads() {
    while (state.uploadsRunning < PARALLEL_UPLOADS && state.uploadQueue.length) {
      const job = state.uploadQueue.shift();
      if (job.item.cancelled) continue;
      state.uploadsRunning += 1;
      upload(job).finally(() => {
        state.uploadsRunning -= 1;
        pumpUploads();
      });
    }
  }

  function uploadItem(file) {
    const fill = el("div", { className: "progress-fill" });
    const bar = el("div", {
      className: "progress", role: "progressbar",
      "aria-valuemin": "0", "aria-valuemax": "100", "aria-valuenow": "0",
      "aria-label": `Upload of ${file.name}`,
    }, fill);
    const status = el("span", { className: "upload-status", text: "Waiting…" });
    const message = el("p", { className: "upload-message" });
    const cancel = el("button", { type: "button", className: "link-button", text: "Cancel" });
    const node = el("li", { className: "upload-item", dataset: { state: "waiting", file: file.name } },
      el("div", { className: "upload-head" },
        el("span", { className: "upload-name", text: file.name }),
        el("span", { className: "upload-size", text: formatBytes(file.size) }),
        status,
        cancel),
      bar,
      message);
    const item = {
      node, cancelled: false, abort: null,
      setProgress(fraction) {
        const pct = Math.max(0, Math.min(100, Math.round(fraction * 100)));
        fill.style.width = `${pct}%`;
        bar.setAttribute("aria-valuenow", String(pct));
      },
      setState(name, text, detail = "") {
        node.dataset.state = name;
        updateClearButton();
        status.textContent = text;
        message.textContent = detail;
        setHidden(cancel, !["waiting", "uploading", "waiting-network"].includes(name));
      },
    };
    cancel.addEventListener("click", () => {
      item.cancelled = true;
      if (item.abort) item.abort();
      else item.setState("cancelled", "Cancelled");
    });
    return item;
  }

  const FINISHED = ["done", "duplicate", "error", "cancelled"];

  function updateClearButton() {
    const items = Array.from(document.querySelectorAll("#upload-list li"));
    setHidden($("upload-clear"), !items.some((li) => FINISHED.includes(li.dataset.state)));
  }

  function clearFinishedUploads() {
    for (const li of document.querySelectorAll("#upload-list li")) {
      if (FINISHED.includes(li.dataset.state)) li.remove();
    }
    updateClearButton();
  }

  // Uploads go through the service's resumable uploads (tus 1.0, /api/v1/uploads) with the
  // vendored tus-js-client (web/vendor/tus.min.js): the file travels in parts; a dropped
  // connection is retried from the offset the server holds, and when the browser says it is
  // offline the upload waits for the network to come back. Each upload's address is kept in
  // localStorage under the file's fingerprint (name, type, size, modification time, server),
  // so choosing the same file again after a reload continues it instead of starting over.
  const UPLOAD_CHUNK_BYTES = 8 * 1024 * 1024;
  const UPLOAD_RETRY_DELAYS = [0, 1000, 2000, 4000, 8000, 15000, 30000, 30000, 60000, 60000];
  const SPEED_WINDOW_MS = 8000;

  function uploadEndpoint() {
    return new URL(`${API}/uploads`, document.baseURI).href;
  }

  /** Speed over the last seconds and the time left, from the bytes sent so far. */
  function rateMeter() {
    const samples = [];
    return {
      reset() { samples.length = 0; },
      text(sent, total) {
        const now = performance.now();
        samples.push([now, sent]);
        while (samples.length > 2 && now - samples[0][0] > SPEED_WINDOW_MS) samples.shift();
        const [t0, b0] = samples[0];
        const seconds = (now - t0) / 1000;
        if (seconds < 0.5 || sent <= b0) return "";
        const speed = (sent - b0) / seconds;
        return `${formatBytes(speed)}/s, ${formatDuration((total - sent) / speed)} left`;
      },
    };
  }

  function formatDuration(seconds) {
    if (!Number.isFinite(seconds) || seconds < 0) return "—";
    if (seconds < 60) return `${Math.max(1, Math.round(seconds))} s`;
    if (seconds < 3600) return `${Math.floor(seconds / 60)} min ${Math.round(seconds % 60)} s`;
    return `${Math.floor(seconds / 3600)} h ${Math.round((seconds % 3600) / 60)} min`;
  }

  function upload({ file, tags, item }) {
    return new Promise((resolve) => {
      const meter = rateMeter();
      let waitingForNetwork = false;
      const metadata = { filename: file.name };
      if (tags) metadata.tags = tags;
      const tusUpload = new window.tus.Upload(file, {
        endpoint: uploadEndpoint(),
        headers: { Authorization: `Bearer ${state.key}`, Accept: "application/json" },
        metadata,
        chunkSize: UPLOAD_CHUNK_BYTES,
        retryDelays: UPLOAD_RETRY_DELAYS,
        storeFingerprintForResuming: true,
        removeFingerprintOnSuccess: true,
        onShouldRetry(err) {
          const status = err.originalResponse ? err.originalResponse.getStatus() : 0;
          if (status === 0 && !navigator.onLine) {
            waitingForNetwork = true; // the "online" event below restarts it
            item.setState("waiting-network", "Waiting for the network…",
              "The connection is gone. The upload continues where it stopped when the network is back.");
            return false;
          }
          return status === 0 || status === 409 || status === 423 || status >= 500;
        },
        onProgress(sent, total) {
          const fraction = total ? sent / total : 0;
          item.setProgress(fraction);
          const rate = meter.text(sent, total);
          item.setState("uploading", `Uploading… ${Math.floor(fraction * 100)}%`,
            `${formatBytes(sent)} of ${formatBytes(total)}${rate ? ` · ${rate}` : ""}`);
          if (sent === total) item.setState("processing", "Reading the recording on the server…");
        },
        onSuccess(payload) {
          window.removeEventListener("online", onOnline);
          state.keyVerified = true;
          item.setProgress(1);
          const response = payload && payload.lastResponse;
          const datasetId = response ? response.getHeader("Loceval-Dataset") : null;
          finished(datasetId).finally(resolve);
        },
        onError(err) {
          if (waitingForNetwork) return; // kept for the "online" event
          window.removeEventListener("online", onOnline);
          const response = err.originalResponse;
          const status = response ? response.getStatus() : 0;
          if (status === 401) {
            item.setState("error", "Not uploaded", UNAUTHORIZED);
            onUnauthorized();
          } else if (status) {
            state.keyVerified = true;
            item.setState("error", "Not uploaded", uploadProblemText(status, "", response.getBody()));
          } else {
            item.setState("error", "Not uploaded",
              "The connection to the server broke and did not come back. Choose the same file again to continue the upload where it stopped.");
          }
          resolve();
        },
      });
      item.abort = () => {
        window.removeEventListener("online", onOnline);
        tusUpload.abort(true).catch(() => {}); // also removes the partial upload on the server
        item.setState("cancelled", "Cancelled");
        resolve();
      };
      function onOnline() {
        if (!waitingForNetwork) return;
        waitingForNetwork = false;
        meter.reset();
        item.setState("uploading", "Resuming…");
        tusUpload.start();
      }
      window.addEventListener("online", onOnline);

      async function finished(datasetId) {
        let upload = null;
        try {
          const id = tusUpload.url ? tusUpload.url.split("/").pop() : null;
          upload = id ? await api(`/uploads/${encodeURIComponent(id)}`) : null;
        } catch {
          upload = null;
        }
        let dataset = upload && upload.dataset;
        if (!dataset && datasetId) {
          try {
            dataset = await api(`/datasets/${encodeURIComponent(datasetId)}`);
          } catch {
            dataset = null;
          }
        }
        const what = dataset ? describeDataset(dataset) : "";
        const report = (dataset && dataset.upload) || (upload && upload.upload) || {};
        if (report.deduplicated) {
          const name = dataset && dataset.name ? ` as “${dataset.name}”` : "";
          item.setState("duplicate", "Already uploaded",
            `These exact bytes were uploaded before${name}. ${what}`.trim());
        } else {
          const notes = Array.isArray(report.notes) ? report.notes.join(" ") : "";
          item.setState("done", "Uploaded", `${what} ${notes}`.trim());
        }
        scheduleDatasetsReload();
      }

      item.setState("uploading", "Uploading… 0%");
      updateClearButton();
      tusUpload.findPreviousUploads().then((previous) => {
        if (item.cancelled) return;
        const endpoint = uploadEndpoint();
        const same = previous.filter((p) => p.uploadUrl && p.uploadUrl.startsWith(endpoint));
        if (same.length) {
          same.sort((a, b) => String(b.creationTime).localeCompare(String(a.creationTime)));
          tusUpload.resumeFromPreviousUpload(same[0]);
          item.setState("uploading", "Resuming an earlier upload of this file…");
        }
        tusUpload.start();
      }, () => tusUpload.start());
    });
  }

  function describeDataset(dataset) {
    const sources = (dataset.inspection && dataset.inspection.sources) || [];
    const kind = dataset.kind ? `${dataset.kind}, ` : "";
    const inspection = dataset.inspection || {};
    if (inspection.kind === "building") return `${buildingSummary(inspection)}.`;
    const table = sources.length ? "" : radioSummary(inspection);
    return `${kind}${table || plural(sources.length, "trajectory source", "trajectory sources")}.`;
  }

  // --- datasets ----------------------------------------------------------------------------

  function scheduleDatasetsReload() {
    clearTimeout(state.datasetsTimer);
    state.datasetsTimer = setTimeout(loadDatasets, 150);
  }

  async function loadDatasets() {
    if (!state.key) return;
    try {
      const page = await api("/datasets");
      state.datasets = Array.isArray(page.items) ? page.items : [];
      renderDatasets(page.count);
      renderSourceSelects();
      renderDeviceSelect();
      renderBuildingSelect();
      renderOtherDatasetChoices();
      renderRadioSelects();
      if (state.history) renderHistory(state.history.items, state.history.count);
    } catch (err) {
      reportError(err);
    }
  }

  function sourceLabel(dataset, source) {
    const name = dataset.name || dataset.filename || dataset.id;
    const where = source.selector ? `${name} @ ${source.selector}` : name;
    const facts = [];
    if (typeof source.pose_count === "number") facts.push(plural(source.pose_count, "pose", "poses"));
    if (typeof source.duration_s === "number") facts.push(formatSeconds(source.duration_s));
    return facts.length ? `${where} (${facts.join(", ")})` : where;
  }

  function sourceValue(datasetId, selector) {
    return JSON.stringify([datasetId, selector === undefined ? null : selector]);
  }

  function renderDatasets(count) {
    const body = $("datasets-body");
    body.replaceChildren();
    for (const dataset of state.datasets) {
      const inspection = dataset.inspection || {};
      const sources = Array.isArray(inspection.sources) ? inspection.sources : [];
      const warnings = Array.isArray(inspection.warnings) ? inspection.warnings : [];
      const tags = Array.isArray(dataset.tags) ? dataset.tags : [];
      const nameCell = el("td", { className: "dataset-name" },
        el("strong", { text: dataset.name || dataset.filename || dataset.id }),
        dataset.filename && dataset.filename !== dataset.name
          ? el("div", { className: "muted small", text: dataset.filename }) : null,
        tags.length ? el("div", { className: "tags" }, tags.map((t) => el("span", { className: "tag", text: t }))) : null,
        el("div", { className: "muted small", text: `Uploaded ${formatTime(dataset.created_at)}` }));
      let sourceList = sources.length
        ? el("ul", { className: "sources" }, sources.map((s) => el("li", {},
          el("code", { text: s.selector === null || s.selector === undefined ? "whole file" : s.selector }),
          s.description ? el("span", { className: "source-desc", text: ` — ${s.description}` }) : null,
          " ",
          el("span", { className: "muted nowrap", text: `· ${[
            typeof s.pose_count === "number" ? plural(s.pose_count, "pose", "poses") : null,
            typeof s.duration_s === "number" ? formatSeconds(s.duration_s) : null,
          ].filter(Boolean).join(", ")}` }))))
        : el("span", { className: "muted", text: dataset.kind === "urdf" ? "No trajectory (device description)"
          : inspection.kind === "building" ? `No trajectory (${buildingSummary(inspection)})`
            : radioSummary(inspection) || "No trajectory found" });
      if (sources.length > 4) {
        const topics = sources.filter((s) => s.kind === "topic").length;
        const summary = `${plural(sources.length, "trajectory source", "trajectory sources")}` +
          (topics && topics < sources.length ? ` (${plural(topics, "topic", "topics")}, ${sources.length - topics} from tf)` : "");
        sourceList = el("details", { className: "sources-more" }, el("summary", { text: summary }), sourceList);
      }
      const warningList = warnings.length
        ? el("ul", { className: "warnings" }, warnings.map((w) => el("li", { text: typeof w === "string" ? w : JSON.stringify(w) })))
        : null;
      const remove = el("button", {
        type: "button", className: "danger small", text: "Delete",
        "aria-label": `Delete ${dataset.name || dataset.id}`,
        onclick: () => deleteDataset(dataset, remove),
      });
      body.append(el("tr", { dataset: { datasetId: dataset.id } },
        nameCell,
        el("td", { "data-label": "Kind" }, el("span", { className: "kind", text: dataset.kind || "?" })),
        el("td", { className: "num", "data-label": "Size", text: formatBytes(dataset.size_bytes) }),
        el("td", { "data-label": "Sources" }, sourceList, warningList),
        el("td", { className: "actions" }, remove)));
    }
    const empty = state.datasets.length === 0;
    setHidden($("datasets-table"), empty);
    setHidden($("datasets-empty"), !empty);
    if (typeof count === "number" && count > state.datasets.length) {
      body.append(el("tr", {}, el("td", { colspan: "5", className: "muted",
        text: `Showing ${state.datasets.length} of ${count} datasets.` })));
    }
  }

  async function deleteDataset(dataset, button) {
    const name = dataset.name || dataset.filename || dataset.id;
    if (!window.confirm(`Delete the dataset “${name}”? This cannot be undone.`)) return;
    button.disabled = true;
    try {
      await api(`/datasets/${encodeURIComponent(dataset.id)}`, { method: "DELETE" });
      await loadDatasets();
    } catch (err) {
      button.disabled = false;
      reportError(err);
    }
  }

  // --- evaluation form ---------------------------------------------------------------------

  function fillSourceSelect(select, placeholder) {
    const previous = select.value;
    select.replaceChildren(el("option", { value: "", text: placeholder }));
    const groups = new Map();
    for (const [value, entry] of state.sources) {
      const option = el("option", { value, text: entry.label });
      const sources = entry.dataset.inspection.sources;
      if (sources.length === 1) {
        select.append(option); // a single-trajectory file needs no group
        continue;
      }
      let group = groups.get(entry.dataset.id);
      if (!group) {
        group = el("optgroup", { label: entry.dataset.name || entry.dataset.filename || entry.dataset.id });
        groups.set(entry.dataset.id, group);
        select.append(group);
      }
      group.append(option);
    }
    select.value = state.sources.has(previous) ? previous : "";
  }

  function renderSourceSelects() {
    state.sources.clear();
    for (const dataset of state.datasets) {
      const sources = (dataset.inspection && dataset.inspection.sources) || [];
      for (const source of sources) {
        state.sources.set(sourceValue(dataset.id, source.selector), {
          dataset, source, label: sourceLabel(dataset, source),
        });
      }
    }
    const none = state.sources.size === 0;
    fillSourceSelect($("reference-select"), none ? "Upload a recording first" : "— choose the ground truth —");
    fillSourceSelect($("ranging-reference-select"), none ? "Upload a recording first" : "— choose the ground truth —");
    for (const select of document.querySelectorAll(".estimate-select")) {
      fillSourceSelect(select, none ? "Upload a recording first" : "— choose an estimate —");
    }
  }

  function addEstimateRow() {
    const fragment = $("estimate-row-template").content.cloneNode(true);
    const row = fragment.querySelector(".estimate-row");
    const select = row.querySelector(".estimate-select");
    fillSourceSelect(select, state.sources.size ? "— choose an estimate —" : "Upload a recording first");
    row.querySelector(".remove-estimate").addEventListener("click", () => {
      row.remove();
      updateEstimateRows();
    });
    $("estimate-rows").append(row);
    updateEstimateRows();
    return row;
  }

  function updateEstimateRows() {
    const rows = document.querySelectorAll(".estimate-row");
    rows.forEach((row, i) => {
      row.querySelector(".estimate-select").setAttribute("aria-label", `Estimate ${i + 1} source`);
      setHidden(row.querySelector(".remove-estimate"), rows.length === 1);
    });
  }

  function parseSource(value) {
    const [dataset_id, selector] = JSON.parse(value);
    return { dataset_id, selector };
  }

  function readForm() {
    const reference = $("reference-select").value;
    if (!reference) throw new Error("Choose the reference (ground truth) trajectory.");
    const estimates = [];
    for (const row of document.querySelectorAll(".estimate-row")) {
      const value = row.querySelector(".estimate-select").value;
      const name = row.querySelector(".estimate-name").value.trim();
      const system = row.querySelector(".estimate-system").value.trim();
      if (!value) {
        if (name) throw new Error(`Choose the source of the estimate named “${name}”.`);
        continue;
      }
      estimates.push({ ...parseSource(value), name: name || null, system: system || null });
    }
    if (!estimates.length) throw new Error("Choose at least one estimate trajectory.");
    return { reference: { ...parseSource(reference), name: null }, estimates, options: readOptions() };
  }

  /** A form problem found before anything is sent: its text names the page's field. */
  class FieldError extends Error {
    constructor(key, message) {
      super(message);
      this.fields = [key];
    }
  }

  /** The options of the evaluation form, as the API's ``options`` object (defaults left out). */
  function readOptions() {
    const options = {
      align: $("opt-align").value,
      association: $("opt-association").value,
      units: $("opt-units").value,
      rpe_unit: $("opt-rpe-unit").value,
    };
    // The tolerance (0.10@95, or a bare 0.10 for 95 %) is checked by the server's own parser;
    // a refused one comes back naming this field.
    const tolerance = $("opt-tolerance").value.trim();
    if (tolerance) options.tolerance = tolerance;
    const numbers = { time_offset_s: "opt-time-offset", max_gap_s: "opt-max-gap", max_dt_s: "opt-max-dt", rpe_delta: "opt-rpe-delta" };
    for (const [key, id] of Object.entries(numbers)) {
      const value = optionNumber(key, $(id).value);
      if (value !== undefined) options[key] = value;
    }
    const alignFirst = $("opt-align-first").value.replace(/\s+/g, "");
    if (alignFirst) {
      checkPattern("align_first", alignFirst);
      options.align_first = alignFirst;
    }
    if ($("opt-stamp").value !== OPTION_DOCS.get("stamp")?.default) options.stamp = $("opt-stamp").value;
    Object.assign(options, readVerdictOptions(), readDeviceOptions(), readCadOptions(), readOtherOptions());
    return options;
  }

  // --- the options document: bounds, choices and help of the form's fields ------------------

  /** The page's name of an option's field (its data-label), or the option's words. */
  function optionLabel(key) {
    const field = optionField(key);
    const doc = OPTION_DOCS.get(key);
    return field ? `“${field.dataset.label}”` : (doc ? doc.words : key);
  }

  /** What is wrong with a number for an option (its kind and bounds); "" when it is fine. */
  function numberProblem(key, value) {
    const doc = OPTION_DOCS.get(key);
    const label = optionLabel(key);
    if (!Number.isFinite(value)) return `${label}: write a number.`;
    if (!doc) return "";
    if (doc.kind === "integer" && !Number.isInteger(value)) return `${label}: write a whole number.`;
    const low = doc.minimum;
    const high = doc.maximum;
    const below = low !== null && (value < low || (doc.exclusive_minimum && value === low));
    if (below || (high !== null && value > high)) return `${label} must be ${doc.bounds}, got ${value}.`;
    return "";
  }

  /** A number typed into an option's field, checked on the page; undefined when empty. */
  function optionNumber(key, text) {
    const trimmed = String(text).trim();
    if (!trimmed) return undefined;
    const doc = OPTION_DOCS.get(key);
    if (doc && doc.auto && trimmed.toLowerCase() === "auto") return "auto";
    const value = Number(trimmed);
    const problem = numberProblem(key, value);
    if (problem) throw new FieldError(key, problem);
    return value;
  }

  /** Check a text against the option's pattern, if the document gives one. */
  function checkPattern(key, text) {
    const doc = OPTION_DOCS.get(key);
    if (!doc || !doc.pattern || new RegExp(doc.pattern).test(text)) return;
    const example = doc.example || doc.metavar;
    throw new FieldError(key, `${optionLabel(key)}: “${text}” is not of the form ${example}.`);
  }

  /** Give each field of the page its option's bounds, choices, default and help. */
  function applyOptionDocs() {
    for (const field of document.querySelectorAll("[data-option]")) {
      const doc = OPTION_DOCS.get(field.dataset.option);
      if (!doc) continue;
      if (!field.title) field.title = doc.help;
      const inputs = "input:not([type=checkbox]), select, textarea";
      const input = field.matches(inputs) ? field : field.querySelector(inputs);
      if (!input) continue;
      if (input.tagName === "SELECT" && doc.choices.length) {
        syncChoices(input, doc);
      } else if (input.type === "number") {
        if (doc.minimum !== null) input.min = String(doc.minimum);
        if (doc.maximum !== null) input.max = String(doc.maximum);
        if (!input.placeholder && doc.default !== null) input.placeholder = String(doc.default);
      } else if (doc.pattern && input.tagName === "INPUT") {
        input.pattern = doc.pattern;
      }
    }
  }

  /** Offer exactly the option's choices, keeping the page's words for the ones it has. */
  function syncChoices(select, doc) {
    const words = new Map(Array.from(select.options).map((o) => [o.value, o.textContent]));
    const chosen = select.value;
    select.replaceChildren(...doc.choices.map((choice) => el("option", {
      value: choice, text: words.get(choice) || choice, selected: choice === doc.default,
    })));
    if (doc.choices.includes(chosen)) select.value = chosen;
  }

  /** Make a field for every option of the document that no field of the page holds. */
  function renderOtherOptions() {
    const grid = $("other-options-grid");
    const fields = [];
    for (const doc of OPTION_DOCS.values()) {
      if (!FORM_GROUPS.has(doc.group) || optionField(doc.key)) continue;
      const input = otherOptionInput(doc);
      if (!input) continue;
      // a short name (the help is the field's tooltip); a row without one: its words
      const words = doc.words.replace(/^the /, "");
      const label = doc.label || words.charAt(0).toUpperCase() + words.slice(1);
      const hint = doc.key === "baseline" ? "an earlier evaluation" : doc.bounds_hint || (doc.kind === "file" ? "an uploaded dataset" : "");
      fields.push(el("label", {
        className: doc.kind === "switch" ? "field field-switch" : "field",
        title: doc.help, dataset: { option: doc.key, label, kind: doc.kind, generated: "" },
      }, el("span", {}, label, hint ? " " : "", hint ? el("small", { text: `(${hint})` }) : ""), input));
    }
    grid.replaceChildren(...fields);
    $("other-options").hidden = !fields.length;
  }

  /** The input of an option made from its document (null: the page cannot offer its kind). */
  function otherOptionInput(doc) {
    // The baseline is an earlier evaluation of this project (the history's succeeded ones).
    if (doc.key === "baseline") return el("select", { className: "evaluation-choice" }, el("option", { value: "", text: NONE }));
    const shown = Array.isArray(doc.default) ? doc.default.join(", ") : doc.default;
    const placeholder = shown === null || shown === undefined ? (doc.example || "") : String(shown);
    switch (doc.kind) {
      case "switch":
        return el("input", { type: "checkbox", checked: doc.default === true });
      case "choice":
        return el("select", {}, ...doc.choices.map((c) => el("option", { value: c, text: c, selected: c === doc.default })));
      case "number":
      case "integer":
        if (doc.auto) return el("input", { type: "text", placeholder: `${placeholder} or auto`, spellcheck: "false", inputmode: "decimal" });
        return el("input", {
          type: "number", step: doc.kind === "integer" ? "1" : "any", placeholder,
          min: doc.minimum === null ? null : String(doc.minimum), max: doc.maximum === null ? null : String(doc.maximum),
          inputmode: doc.kind === "integer" ? "numeric" : "decimal",
        });
      case "text":
      case "numbers":
      case "names":
        return el("input", { type: "text", placeholder, spellcheck: "false", pattern: doc.pattern || null });
      case "file":
        return el("select", { className: "dataset-choice" }, el("option", { value: "", text: NONE }));
      default:
        return null; // a matrix or a device file: the page's own fields hold these
    }
  }

  /** Offer the uploaded datasets in the made fields that name one (kind file). */
  function renderOtherDatasetChoices() {
    const choices = state.datasets.map((d) => ({ value: d.id, text: datasetLabel(d) }));
    for (const select of document.querySelectorAll("#other-options-grid select.dataset-choice")) {
      fillChoice(select, choices, NONE, NONE);
    }
  }

  /** The made fields' options, as the API's ``options`` (left out when empty or the default). */
  function readOtherOptions() {
    const options = {};
    for (const field of document.querySelectorAll("#other-options-grid [data-option]")) {
      const key = field.dataset.option;
      const doc = OPTION_DOCS.get(key);
      const input = field.querySelector("input, select");
      if (doc.kind === "switch") {
        if (input.checked !== (doc.default === true)) options[key] = input.checked;
        continue;
      }
      const text = input.value.trim();
      if (!text || text === String(doc.default)) continue;
      if (doc.kind === "number" || doc.kind === "integer") {
        options[key] = optionNumber(key, text);
      } else if (doc.kind === "numbers") {
        const values = numberList(text, key, field.dataset.label);
        for (const value of values) {
          const problem = numberProblem(key, value);
          if (problem) throw new FieldError(key, problem);
        }
        options[key] = values;
      } else if (doc.kind === "names") {
        options[key] = text.split(/[\s,;]+/).filter(Boolean);
      } else {
        if (doc.kind === "text") checkPattern(key, text);
        options[key] = text;
      }
    }
    return options;
  }

  /** A list of numbers typed with commas or spaces (``0.05, 0.10``); throws naming the field. */
  function numberList(text, key, label) {
    const parts = text.split(/[\s,;]+/).filter(Boolean);
    const values = parts.map(Number);
    const bad = parts.find((p, i) => !Number.isFinite(values[i]));
    if (bad !== undefined) throw new FieldError(key, `${label}: “${bad}” is not a number.`);
    return values;
  }

  function readVerdictOptions() {
    const options = {};
    const thresholds = $("opt-thresholds").value.trim();
    if (thresholds) {
      const values = numberList(thresholds, "thresholds_m", "Thresholds");
      for (const value of values) {
        const problem = numberProblem("thresholds_m", value);
        if (problem) throw new FieldError("thresholds_m", problem);
      }
      options.thresholds_m = values;
    }
    const worst = optionNumber("worst", $("opt-worst").value);
    if (worst !== undefined) options.worst = worst;
    return options;
  }

  function readDeviceOptions() {
    const options = {};
    const offset = $("opt-offset").value.trim();
    if (offset) options.offset = offset.replace(/[\s,]+/g, " ");
    const datasetId = $("opt-device-dataset").value;
    const fromLink = $("opt-device-from").value.trim();
    const toLink = $("opt-device-to").value.trim();
    if (datasetId) {
      if (!fromLink) throw new FieldError("device.from_link", "From link: name the link the device offset starts at (e.g. base_link).");
      if (!toLink) throw new FieldError("device.to_link", "To link: name the device's link (e.g. lidar_link).");
      options.device = { dataset_id: datasetId, from_link: fromLink, to_link: toLink };
    } else if (fromLink || toLink) {
      throw new FieldError("device", "Device file: choose the URDF or bag that holds the two links.");
    }
    return options;
  }

  function readCadOptions() {
    const options = {};
    const site = $("opt-site").value.trim();
    if (site) options.site = site.replace(/[\s,]+/g, " ");
    const matrix = $("opt-site-matrix").value.trim();
    if (matrix) {
      const rows = matrix.split(/\n+/).map((line) => line.trim()).filter(Boolean);
      const values = rows.map((row) => numberList(row, "site_matrix", "Site matrix"));
      if (values.length !== 4 || values.some((row) => row.length !== 4)) {
        throw new FieldError("site_matrix", "Site matrix: write 4 rows of 4 numbers, one row per line.");
      }
      options.site_matrix = values;
    }
    const simplify = optionNumber("simplify_m", $("opt-simplify").value);
    if (simplify !== undefined) options.simplify_m = simplify;
    const building = $("opt-building").value;
    if (building) options.building = building;
    const up = $("opt-building-up");
    if (up.value !== up.querySelector("option[selected]")?.value) options.building_up = up.value;
    const boxes = Array.from(document.querySelectorAll("#format-boxes input"));
    const chosen = boxes.filter((b) => b.checked).map((b) => b.value);
    if (chosen.length < boxes.length) options.formats = chosen;
    return options;
  }

  function renderFormatBoxes() {
    const holder = $("format-boxes");
    holder.replaceChildren(...ALL_ARTIFACTS.map((name) => el("label", {},
      el("input", {
        type: "checkbox", value: name,
        checked: name !== "report.pdf" || PDF_REPORTS,
        // result.json: always written (the figures); report.pdf: this server cannot write PDFs
        disabled: name === "result.json" || (name === "report.pdf" && !PDF_REPORTS),
      }),
      el("span", { text: name }))));
  }

  /** Fill the device file choice with the uploaded URDFs and bags. */
  function renderDeviceSelect() {
    const choices = [];
    for (const dataset of state.datasets) {
      const format = dataset.inspection && dataset.inspection.format;
      if (format !== "urdf" && format !== "bag") continue;
      choices.push({
        value: dataset.id,
        text: `${dataset.name || dataset.filename || dataset.id} (${format === "urdf" ? "URDF" : "bag"})`,
      });
    }
    fillChoice($("opt-device-dataset"), choices, NONE, NONE);
    renderDeviceLinks();
  }

  /** What an uploaded building model holds, for the datasets list and the building choice. */
  function buildingSummary(inspection) {
    const facts = [`${String(inspection.format || "").toUpperCase()} building model`.trim()];
    if (typeof inspection.faces === "number") facts.push(plural(inspection.faces, "face", "faces"));
    if (typeof inspection.segments === "number") facts.push(`floor plan, ${plural(inspection.segments, "line", "lines")}`);
    if (inspection.georeferenced) facts.push(`georeferenced${inspection.crs ? ` (${inspection.crs})` : ""}`);
    return facts.join(", ");
  }

  /** Fill the building model choice with the uploaded building models (options.building). */
  function renderBuildingSelect() {
    const choices = [];
    for (const dataset of state.datasets) {
      const inspection = dataset.inspection || {};
      if (inspection.kind !== "building") continue;
      choices.push({ value: dataset.id, text: `${datasetLabel(dataset)} (${buildingSummary(inspection)})` });
    }
    fillChoice($("opt-building"), choices, NONE, NONE);
  }

  /** Offer the chosen device file's links (URDF) or tf frames (bag) for the two link fields. */
  function renderDeviceLinks() {
    const dataset = state.datasets.find((d) => d.id === $("opt-device-dataset").value);
    const inspection = (dataset && dataset.inspection) || {};
    const links = Array.isArray(inspection.links)
      ? inspection.links
      : (Array.isArray(inspection.tf_tree) ? inspection.tf_tree.map((f) => f.frame) : []);
    $("device-links").replaceChildren(...links.map((name) => el("option", { value: String(name) })));
  }

  async function startEvaluation(event) {
    event.preventDefault();
    const errorText = $("eval-form-error");
    errorText.textContent = "";
    clearInvalid($("eval-form"));
    let body;
    try {
      body = readForm();
    } catch (err) {
      errorText.textContent = err.message;
      if (err.fields) markInvalid(err.fields);
      return;
    }
    const button = $("start-button");
    button.disabled = true;
    try {
      const evaluation = await api("/evaluations", { method: "POST", json: body });
      watch(evaluation.id, evaluation);
      loadHistory();
    } catch (err) {
      reportError(err, errorText);
      if (err instanceof ApiError) markInvalid(err.fields);
    } finally {
      button.disabled = false;
    }
  }


  // --- ranging evaluation ------------------------------------------------------------------
  // Anchors and ranges are uploads of their own kinds; the job is an evaluation like the
  // others (POST /ranging), so progress, summary and files show in the same card.

  const RANGE_MSGTYPE = "sensor_msgs/msg/Range";

  /** What a table without a trajectory holds, for the datasets list ("13 surveyed points"). */
  function radioSummary(inspection) {
    if (inspection.format === "anchors" && Array.isArray(inspection.anchors)) {
      return plural(inspection.anchors.length, "radio anchor", "radio anchors");
    }
    if (inspection.format === "points" && Array.isArray(inspection.ids)) {
      return `${plural(inspection.ids.length, "surveyed point", "surveyed points")} (control points or radio anchors)`;
    }
    if (inspection.format === "ranges" && typeof inspection.ranges === "number") {
      const anchors = Array.isArray(inspection.anchor_ids) ? inspection.anchor_ids.length : 0;
      return `${plural(inspection.ranges, "range", "ranges")} to ${plural(anchors, "anchor", "anchors")}`;
    }
    return "";
  }

  function datasetLabel(dataset) {
    return dataset.name || dataset.filename || dataset.id;
  }

  /** The anchors (anchors or surveyed points tables) and the ranges (tables, bags' Range topics). */
  function radioChoices() {
    const anchors = [];
    const ranges = [];
    for (const dataset of state.datasets) {
      const inspection = dataset.inspection || {};
      if (inspection.format === "anchors" || inspection.format === "points") {
        const ids = inspection.format === "anchors" ? inspection.anchors : inspection.ids;
        const count = Array.isArray(ids) ? ` (${plural(ids.length, "anchor", "anchors")})` : "";
        anchors.push({ value: dataset.id, text: `${datasetLabel(dataset)}${count}` });
      } else if (inspection.format === "ranges") {
        const what = radioSummary(inspection);
        ranges.push({ value: sourceValue(dataset.id, null), text: `${datasetLabel(dataset)}${what ? ` (${what})` : ""}` });
      } else if (inspection.format === "bag") {
        for (const topic of Array.isArray(inspection.topics) ? inspection.topics : []) {
          if (topic.msgtype !== RANGE_MSGTYPE) continue;
          const count = typeof topic.message_count === "number" ? ` (${plural(topic.message_count, "range", "ranges")})` : "";
          ranges.push({ value: sourceValue(dataset.id, topic.name), text: `${datasetLabel(dataset)} @ ${topic.name}${count}` });
        }
      }
    }
    return { anchors, ranges };
  }

  /** Offer ``choices`` ({value, text}) after an empty one, keeping the choice made if offered. */
  function fillChoice(select, choices, empty, placeholder) {
    const previous = select.value;
    select.replaceChildren(el("option", { value: "", text: choices.length ? placeholder : empty }),
      ...choices.map((c) => el("option", { value: c.value, text: c.text })));
    select.value = choices.some((c) => c.value === previous) ? previous : "";
  }

  function renderRadioSelects() {
    const { anchors, ranges } = radioChoices();
    // short choices (a select cuts its text); the fields' labels say what to upload
    fillChoice($("ranging-anchors-select"), anchors, "— none uploaded yet —", "— choose the anchors —");
    fillChoice($("ranging-ranges-select"), ranges, "— none uploaded yet —", "— choose the ranges —");
  }

  /** The tag height applies to 2D positioning only. */
  function updateTagHeight() {
    $("ranging-tag-height").disabled = $("ranging-dims").value !== "2";
  }

  /** The ranging options as the API's ``options`` object (defaults left out). */
  function readRangingOptions() {
    const options = {};
    const solve = Array.from(document.querySelectorAll("input[name=ranging-solve]:checked")).map((b) => b.value);
    if (!solve.length) throw new FieldError("solve", "Solvers: choose at least one (nlls or minmax).");
    options.solve = solve;
    options.dims = $("ranging-dims").value;
    const numbers = {
      epoch_s: "ranging-epoch", tag_height_m: "ranging-tag-height",
      outlier_threshold_m: "ranging-outlier", distance_bin_m: "ranging-distance-bin",
    };
    for (const [key, id] of Object.entries(numbers)) {
      if ($(id).disabled) continue;
      const value = optionNumber(key, $(id).value);
      if (value !== undefined) options[key] = value;
    }
    const offset = $("ranging-tag-offset").value.trim();
    if (offset) options.tag_offset_xyz = offset.replace(/[\s,]+/g, " ");
    return options;
  }

  function readRangingForm() {
    const reference = $("ranging-reference-select").value;
    if (!reference) throw new Error("Choose the reference (ground truth) trajectory.");
    const anchors = $("ranging-anchors-select").value;
    if (!anchors) throw new Error("Choose the anchors (an uploaded id,x,y,z table).");
    const ranges = $("ranging-ranges-select").value;
    if (!ranges) throw new Error("Choose the ranges (an uploaded t,anchor_id,range_m table or a bag's Range topic).");
    const source = parseSource(ranges);
    return {
      reference: { ...parseSource(reference), name: null },
      anchors,
      ranges: source.selector === null ? source.dataset_id : source,
      options: readRangingOptions(),
    };
  }

  async function startRanging(event) {
    event.preventDefault();
    const form = $("ranging-form");
    const errorText = $("ranging-form-error");
    errorText.textContent = "";
    clearInvalid(form);
    let body;
    try {
      body = readRangingForm();
    } catch (err) {
      errorText.textContent = err.message;
      if (err.fields) markInvalid(err.fields);
      return;
    }
    const button = $("ranging-start-button");
    button.disabled = true;
    try {
      const evaluation = await api("/ranging", { method: "POST", json: body });
      watch(evaluation.id, evaluation);
      loadHistory();
      $("current-card").scrollIntoView({ behavior: "smooth", block: "start" });
    } catch (err) {
      reportError(err, errorText);
      if (err instanceof ApiError) markInvalid(err.fields);
    } finally {
      button.disabled = false;
    }
  }

  function formatShare(x) {
    return typeof x === "number" && Number.isFinite(x) ? `${(x * 100).toFixed(1)} %` : "—";
  }

  /** The ranging figures of a finished ranging evaluation: overall, then per anchor. */
  function renderRanging(evaluation) {
    const ranging = evaluation.result && evaluation.result.ranging;
    setHidden($("current-ranging"), !ranging);
    if (!ranging) return;
    const anchors = Array.isArray(ranging.anchors) ? ranging.anchors : [];
    const unit = lengthUnit([ranging.overall || {}, ...anchors].flatMap((s) => [s.bias_m, s.std_m, s.rmse_m]));
    const row = (name, s, className) => el("tr", { className },
      el("th", { scope: "row", className: "name", text: name }),
      el("td", { className: "num", "data-label": "Ranges", text: typeof s.n === "number" ? s.n.toLocaleString() : "—" }),
      el("td", { className: "num", "data-label": "Bias", text: formatMetres(s.bias_m, unit) }),
      el("td", { className: "num", "data-label": "Std", text: formatMetres(s.std_m, unit) }),
      el("td", { className: "num ranging-rmse", "data-label": "RMSE", dataset: { valueM: String(s.rmse_m) }, text: formatMetres(s.rmse_m, unit) }),
      el("td", { className: "num", "data-label": "Outliers", text: formatShare(s.outlier_share) }));
    $("ranging-body").replaceChildren(
      row("All anchors", ranging.overall || {}, "overall"),
      ...anchors.map((a) => row(String(a.id), a, "anchor")));
    const unused = Array.isArray(ranging.unused_anchors) ? ranging.unused_anchors : [];
    const notes = [`Error = measured − true distance; an outlier is beyond ${formatMetres(ranging.outlier_threshold_m)}.`];
    if (unused.length) notes.push(`Never heard: ${unused.join(", ")}.`);
    $("ranging-note").textContent = notes.join(" ");
  }

  // --- current evaluation ------------------------------------------------------------------

  function stopWatching() {
    clearTimeout(state.watchTimer);
    state.watchTimer = null;
    state.watchSeq += 1;
  }

  function isActive(status) {
    return status === "queued" || status === "running";
  }

  function watch(id, initial = null) {
    stopWatching();
    const seq = state.watchSeq;
    state.watchId = id;
    setHidden($("current-card"), false);
    $("current-id").textContent = id.slice(0, 8);
    $("current-id").title = id;
    markHistoryRow();
    let failures = 0;
    let sawActive = false;

    const show = (evaluation) => {
      renderEvaluation(evaluation);
      if (isActive(evaluation.status)) sawActive = true;
      else if (sawActive) loadHistory(); // it just finished: refresh the table
    };

    const tick = async () => {
      if (seq !== state.watchSeq) return;
      try {
        const evaluation = await api(`/evaluations/${encodeURIComponent(id)}`);
        if (seq !== state.watchSeq) return;
        failures = 0;
        show(evaluation);
        if (isActive(evaluation.status)) state.watchTimer = setTimeout(tick, POLL_MS);
      } catch (err) {
        if (seq !== state.watchSeq) return;
        if (err instanceof ApiError && err.status === 401) return;
        if (err instanceof ApiError && err.status === 0) {
          failures += 1;
          $("current-stage").textContent = `Lost the connection to the server; trying again (${failures})…`;
          state.watchTimer = setTimeout(tick, Math.min(POLL_MS * 2 ** failures, 10000));
          return;
        }
        showProblem(err.message);
      }
    };

    if (initial) show(initial);
    if (!initial || isActive(initial.status)) state.watchTimer = setTimeout(tick, initial ? POLL_MS : 0);
  }

  function datasetName(id) {
    const dataset = state.datasets.find((d) => d.id === id);
    return dataset ? dataset.name || dataset.filename : `dataset ${String(id).slice(0, 8)}`;
  }

  function inputName(input) {
    if (!input) return "?";
    if (input.name) return input.name;
    const base = datasetName(input.dataset_id);
    return input.selector ? `${base} @ ${input.selector}` : base;
  }

  function estimateNames(evaluation) {
    if (Array.isArray(evaluation.summary) && evaluation.summary.length) {
      return evaluation.summary.map((s) => s.name);
    }
    return (evaluation.estimates || []).map(inputName);
  }

  function statusBadge(status) {
    const labels = { queued: "Queued", running: "Running", succeeded: "Succeeded", failed: "Failed" };
    return el("span", { className: `status status-${status}`, text: labels[status] || status });
  }

  function showProblem(text, title = "") {
    const box = $("current-error");
    box.replaceChildren(
      title ? el("strong", { text: title }) : null,
      title ? " " : null,
      el("span", { className: "problem-detail", text }));
    setHidden(box, false);
  }

  function renderEvaluation(evaluation) {
    const { status } = evaluation;
    $("current-status").replaceWith(Object.assign(statusBadge(status), { id: "current-status" }));
    const card = $("current-card");
    card.dataset.status = status;
    card.dataset.evaluationId = evaluation.id;

    const meta = [`Reference: ${inputName(evaluation.reference)}`, `Estimates: ${estimateNames(evaluation).join(", ")}`];
    meta.push(`Started ${formatTime(evaluation.created_at)}`);
    if (evaluation.started_at && evaluation.finished_at) {
      const took = (new Date(evaluation.finished_at) - new Date(evaluation.started_at)) / 1000;
      if (Number.isFinite(took)) meta.push(`took ${formatSeconds(took)}`);
    }
    $("current-meta").textContent = meta.join(" · ");

    const progress = evaluation.progress || {};
    let fraction = typeof progress.fraction === "number" ? progress.fraction : 0;
    if (status === "succeeded") fraction = 1;
    const pct = Math.round(Math.max(0, Math.min(1, fraction)) * 100);
    $("current-fill").style.width = `${pct}%`;
    $("current-bar").setAttribute("aria-valuenow", String(pct));
    $("current-bar").dataset.state = status;
    let stage = progress.stage || "";
    if (status === "queued") stage = "Waiting in the queue for a worker…";
    else if (status === "running") {
      // a stage that names an end ("done") is not what a running job is doing
      const doing = !stage || /^(done|finished|succeeded)$/i.test(stage) ? "working" : stage;
      stage = `${capitalize(doing)}… ${pct}%`.replace(/……/, "…");
    }
    else if (status === "succeeded") stage = "Finished.";
    else if (status === "failed") stage = stage && stage !== "failed" ? `Failed while ${stage}.` : "";
    $("current-stage").textContent = stage;

    if (status === "failed") {
      const problem = evaluation.error || {};
      showProblem(nameFields(problem.detail || problem.title || "No reason was given."), "The evaluation failed:");
    } else {
      setHidden($("current-error"), true);
    }

    // The figures show the moment result.json exists (a running evaluation's result); the
    // files follow as each is written, the list growing with every poll.
    if (status === "succeeded" || (status === "running" && evaluation.result)) {
      renderSummary(evaluation);
      renderRanging(evaluation);
      renderArtifacts(evaluation);
      renderViewer(evaluation);
      setHidden($("current-result"), false);
    } else {
      setHidden($("current-result"), true);
    }
  }

  const UNDECIDED_TITLE = "Undecided: the 95 % interval of the share within the tolerance " +
    "straddles the required share, so this run cannot tell whether it meets it: record a longer run.";

  /** The badge of a verdict, worded as the report words it. */
  function verdictBadge(verdict) {
    if (verdict === "pass") return el("span", { className: "verdict verdict-pass", text: "PASS" });
    if (verdict === "fail") return el("span", { className: "verdict verdict-fail", text: "FAIL" });
    if (verdict === "undecided") {
      return el("span", { className: "verdict verdict-undecided", text: "UNDECIDED", title: UNDECIDED_TITLE });
    }
    return el("span", { className: "verdict verdict-none", text: "no tolerance", title: "Set a tolerance to get a pass/fail verdict" });
  }

  /** A share (0..1) as a percentage with one decimal, as the report prints it. */
  function formatPercent(x) {
    return `${(x * 100).toFixed(1)} %`;
  }

  /**
   * What the verdict rests on, from the result document's verdict: the share within the
   * tolerance, its 95 % interval and the share required (“96.1 % within 0.1 m, 95 % interval
   * 90.7–100.0 %, 95 % required”).
   */
  function verdictFacts(verdict) {
    if (!verdict || typeof verdict.share_within !== "number") return "";
    const parts = [`${formatPercent(verdict.share_within)} within ${verdict.tolerance_m} m`];
    if (Array.isArray(verdict.ci95) && verdict.ci95.length === 2) {
      const [lo, hi] = verdict.ci95;
      parts.push(`95 % interval ${(lo * 100).toFixed(1)}–${(hi * 100).toFixed(1)} %`);
    }
    if (typeof verdict.required_share === "number") parts.push(`${+(verdict.required_share * 100).toFixed(4)} % required`);
    return parts.join(", ");
  }

  /** The result's systems of trials (each with its trials and failed trials), or []. */
  function resultSystems(evaluation) {
    const systems = evaluation.result && Array.isArray(evaluation.result.systems) ? evaluation.result.systems : [];
    return systems.filter((s) => s && typeof s.name === "string");
  }

  /** A system's group row: its trials, failed trials and ATE/RPE over trials (median, interval). */
  function systemRow(system, unit) {
    const figures = [["ATE RMSE", "ate_rmse"], ["RPE RMSE", "rpe_rmse"]].map(([label, key]) => {
      const m = system.metrics && system.metrics[key];
      if (!m || m.unit !== "m") return null;
      const interval = m.interval ? `, 95 % interval of the mean ${formatMetres(m.interval.low, unit)} to ${formatMetres(m.interval.high, unit)}` : ", too few trials for an interval";
      return `${label} median ${formatMetres(m.median, unit)} (spread ${formatMetres(m.min, unit)} to ${formatMetres(m.max, unit)}${interval})`;
    }).filter(Boolean);
    const failed = (system.failed || []).length;
    const count = `${(system.trials || []).length} trials${failed ? `, ${failed} failed` : ""}`;
    return el("tr", { className: "system-row", dataset: { system: system.name } },
      el("th", { scope: "rowgroup", colspan: "5" },
        el("span", { className: "system-name", text: system.name }),
        el("span", { className: "muted small", text: ` · ${count}` }),
        figures.length ? el("div", { className: "muted small system-figures", text: figures.join(" · ") }) : null));
  }

  function renderSummary(evaluation) {
    const body = $("summary-body");
    body.replaceChildren();
    const estimates = (evaluation.result && Array.isArray(evaluation.result.estimates)) ? evaluation.result.estimates : [];
    const unit = lengthUnit((evaluation.summary || []).flatMap((row) => [row.ate_rmse_m, row.rpe_rmse_m]));
    const rows = (evaluation.summary || []).map((row, i) => ({ row, i, system: estimates[i] && estimates[i].system }));
    // Trials are grouped under their system (the result's order), then the other estimates.
    const ordered = [];
    for (const system of resultSystems(evaluation)) {
      ordered.push({ system });
      const trials = rows.filter((r) => r.system === system.name);
      for (const failed of system.failed || []) {
        // A trial that lost tracking keeps its figures (shown, not counted): its row says so.
        const shown = trials.find((r) => r.row.name === failed.name);
        if (shown) shown.failed = failed;
      }
      ordered.push(...trials);
      for (const failed of system.failed || []) {
        if (!trials.some((r) => r.row.name === failed.name)) ordered.push({ failed, of: system.name });
      }
    }
    ordered.push(...rows.filter((r) => !r.system));
    for (const item of ordered) {
      if (item.system !== undefined && !item.row) {
        body.append(systemRow(item.system, unit));
        continue;
      }
      if (item.failed && !item.row) {
        body.append(el("tr", { className: "trial-row trial-failed", dataset: { system: item.of } },
          el("th", { scope: "row", className: "name", text: item.failed.name }),
          el("td", { colspan: "4", className: "muted", "data-label": "Failed" },
            el("span", { className: "verdict verdict-fail", text: "FAILED TRIAL" }), ` ${item.failed.reason}`)));
        continue;
      }
      const { row, i } = item;
      const facts = verdictFacts(estimates[i] && estimates[i].verdict);
      const rowClass = item.failed ? "trial-row trial-failed" : item.system ? "trial-row" : null;
      body.append(el("tr", { className: rowClass, dataset: item.system ? { system: item.system } : {} },
        el("th", { scope: "row", className: "name", text: row.name }),
        el("td", { className: "num ate", "data-label": "ATE RMSE", dataset: { valueM: String(row.ate_rmse_m) }, text: formatMetres(row.ate_rmse_m, unit) }),
        el("td", { className: "num", "data-label": "RPE RMSE", text: formatMetres(row.rpe_rmse_m, unit) }),
        el("td", { className: "num", "data-label": "Matched", text: typeof row.matched === "number" ? row.matched.toLocaleString() : "—" }),
        el("td", { className: "verdict-cell", "data-label": "Verdict" }, verdictBadge(row.verdict),
          facts ? el("div", { className: "muted small verdict-facts", text: facts }) : null,
          item.failed ? el("div", { className: "muted small" },
            el("span", { className: "verdict verdict-fail", text: "FAILED TRIAL" }), ` ${item.failed.reason}`) : null)));
    }
    renderTrials(evaluation);
    renderBaseline(evaluation);
    renderGate(evaluation);
  }

  /** The systems compared over all their trials, one sentence each. */
  function renderTrials(evaluation) {
    const comparisons = evaluation.result && Array.isArray(evaluation.result.system_comparisons) ? evaluation.result.system_comparisons : [];
    const list = $("system-comparisons");
    list.replaceChildren(...comparisons.map((c) => el("li", { dataset: { verdict: c.verdict }, text: c.summary })));
    setHidden($("current-trials"), comparisons.length === 0);
  }

  const BASELINE_WORDS = { better: "BETTER", worse: "WORSE", within_noise: "WITHIN NOISE", undetermined: "UNDETERMINED" };
  const BASELINE_CLASS = { better: "verdict-pass", worse: "verdict-fail", within_noise: "verdict-none", undetermined: "verdict-undecided" };

  /** Each estimate and system against the baseline: difference, interval, verdict. */
  function renderBaseline(evaluation) {
    const baseline = evaluation.result && evaluation.result.baseline;
    const holder = $("current-baseline");
    if (!baseline || typeof baseline !== "object") {
      setHidden(holder, true);
      return;
    }
    const comparisons = Array.isArray(baseline.comparisons) ? baseline.comparisons : [];
    const metres = comparisons.filter((c) => c.unit === "m");
    const unit = lengthUnit(metres.flatMap((c) => [c.current, c.baseline]));
    const signed = (m) => (typeof m === "number" && m > 0 ? "+" : "") + formatMetres(m, unit);
    $("baseline-label").textContent = baseline.label || baseline.source || "";
    $("baseline-body").replaceChildren(...metres.map((c) => el("tr", { dataset: { verdict: c.verdict, level: c.level } },
      el("th", { scope: "row", className: "name", text: c.level === "system" ? `${c.name} (system)` : c.name }),
      el("td", { "data-label": "Metric", text: c.metric === "ate_rmse" ? "ATE RMSE" : "RPE RMSE" }),
      el("td", { className: "num", "data-label": "Now", text: formatMetres(c.current, unit) }),
      el("td", { className: "num", "data-label": "Baseline", text: formatMetres(c.baseline, unit) }),
      el("td", { className: "num", "data-label": "Difference", text: signed(c.difference) }),
      el("td", { className: "num", "data-label": "95 % interval",
        text: Array.isArray(c.interval) ? `${signed(c.interval[0])} to ${signed(c.interval[1])}${c.paired ? " (paired)" : ""}` : "—" }),
      el("td", { className: "verdict-cell", "data-label": "Verdict" },
        el("span", { className: `verdict ${BASELINE_CLASS[c.verdict] || "verdict-none"}`, text: BASELINE_WORDS[c.verdict] || c.verdict })))));
    const notes = Array.isArray(baseline.notes) ? baseline.notes : [];
    $("baseline-notes").replaceChildren(...notes.map((n) => el("li", { text: n })));
    setHidden(holder, false);
  }

  /** The gate of options.fail_on (what `loceval evaluate --fail-on` exits 3 for): passed or
   * closed, and why; hidden without conditions. */
  function renderGate(evaluation) {
    const gate = evaluation.gate;
    const holder = $("current-gate");
    if (!gate || typeof gate !== "object") {
      setHidden(holder, true);
      return;
    }
    const status = $("gate-status");
    status.textContent = gate.passed ? "PASSED" : "CLOSED";
    status.className = `verdict ${gate.passed ? "verdict-pass" : "verdict-fail"}`;
    $("gate-conditions").textContent = `fails on ${(gate.fail_on || []).join(", ")}`;
    const reasons = Array.isArray(gate.reasons) ? gate.reasons : [];
    $("gate-reasons").replaceChildren(...reasons.map((r) => el("li", { text: r })));
    setHidden(holder, false);
  }

  function artifactUrl(evaluation, artifact) {
    const fallback = `${API}/evaluations/${encodeURIComponent(evaluation.id)}/artifacts/${encodeURIComponent(artifact.name)}`;
    if (!artifact.url) return fallback;
    try {
      // The API builds absolute URLs from the Host it saw; behind a proxy that may not be the
      // address this page came from, and the key must only ever go to this page's server.
      const url = new URL(artifact.url, window.location.href);
      return url.origin === window.location.origin ? url.href : `${url.pathname}${url.search}`;
    } catch {
      return fallback;
    }
  }

  function renderArtifacts(evaluation) {
    const list = $("artifact-list");
    list.replaceChildren();
    const artifacts = [...(evaluation.artifacts || [])].sort((a, b) => {
      const rank = (x) => (OPENED_IN_TAB.has(x.name) ? 0 : 1) * 100 + (ALL_ARTIFACTS.indexOf(x.name) + 1 || 99);
      return rank(a) - rank(b) || a.name.localeCompare(b.name);
    });
    const running = evaluation.status === "running";
    if (!artifacts.length && !running) {
      list.append(el("li", { className: "muted", text: "This evaluation produced no files." }));
      return;
    }
    for (const artifact of artifacts) {
      const open = OPENED_IN_TAB.has(artifact.name);
      const message = el("span", { className: "error-text" });
      const label = open
        ? `Open ${artifact.name === "report.pdf" ? "PDF report" : "report"}`
        : `Download ${artifact.name}`;
      const button = el("button", {
        type: "button",
        className: open ? "primary small" : "secondary small",
        dataset: { artifact: artifact.name },
        text: label,
      });
      button.addEventListener("click", () => fetchArtifact(evaluation, artifact, open, button, message));
      list.append(el("li", {},
        button,
        el("span", { className: "muted small", text: ` ${artifact.name} · ${formatBytes(artifact.size_bytes)}` }),
        open ? el("button", {
          type: "button", className: "link-button small", text: "download",
          "aria-label": `Download ${artifact.name}`,
          onclick: () => fetchArtifact(evaluation, artifact, false, null, message),
        }) : null,
        message));
    }
    if (running) {
      list.append(el("li", { className: "muted artifacts-pending", text: "More files follow as each is written…" }));
    }
  }

  // The interactive viewer: the evaluation's viewer.html (code and data inlined, no request of
  // its own) fetched with the key and shown in a sandboxed frame of its own (opaque origin).
  async function renderViewer(evaluation) {
    const holder = $("current-viewer");
    const artifact = (evaluation.artifacts || []).find((a) => a.name === "viewer.html");
    if (!artifact) {
      delete holder.dataset.evaluation;
      holder.replaceChildren();
      setHidden(holder, true);
      return;
    }
    if (holder.dataset.evaluation === evaluation.id) return; // shown already: polling again
    holder.dataset.evaluation = evaluation.id;
    setHidden(holder, false);
    holder.replaceChildren(el("p", { className: "hint", text: "Loading the interactive view…" }));
    try {
      const response = await apiFetch(artifactUrl(evaluation, artifact));
      const page = await response.text();
      if (holder.dataset.evaluation !== evaluation.id) return; // another evaluation by now
      const frame = el("iframe", {
        className: "viewer-frame", title: "Interactive view of the paths", sandbox: "allow-scripts",
      });
      frame.srcdoc = page;
      holder.replaceChildren(frame);
    } catch (err) {
      const message = el("p", { className: "error-text" });
      reportError(err, message);
      holder.replaceChildren(message);
    }
  }

  async function fetchArtifact(evaluation, artifact, inTab, button, message) {
    message.textContent = "";
    // Open the tab now, while the click still counts as a user action, and fill it later.
    let tab = null;
    if (inTab) {
      tab = window.open("", "_blank");
      if (tab) {
        try {
          tab.document.title = `Loading ${artifact.name}…`;
          tab.document.body.textContent = `Loading ${artifact.name}…`;
        } catch {
          // not ours to write to: it is only a placeholder
        }
      }
    }
    if (button) button.disabled = true;
    try {
      const response = await apiFetch(artifactUrl(evaluation, artifact));
      const data = await response.blob();
      const type = artifact.media_type || data.type || "application/octet-stream";
      const url = URL.createObjectURL(new Blob([data], { type }));
      setTimeout(() => URL.revokeObjectURL(url), 5 * 60 * 1000);
      if (inTab && tab && !tab.closed) {
        tab.location.href = url;
      } else if (!inTab || !window.open(url, "_blank")) {
        const link = el("a", { href: url, download: artifact.filename || artifact.name, hidden: true });
        document.body.append(link);
        link.click();
        link.remove();
        if (inTab) message.textContent = " The browser blocked the new tab, so the file was downloaded instead.";
      }
    } catch (err) {
      if (tab) tab.close();
      reportError(err, message);
      if (message.textContent) message.textContent = ` ${message.textContent}`;
    } finally {
      if (button) button.disabled = false;
    }
  }

  // --- history -----------------------------------------------------------------------------

  function stopHistoryPolling() {
    clearTimeout(state.historyTimer);
    state.historyTimer = null;
  }

  function markHistoryRow() {
    for (const row of document.querySelectorAll("#history-body tr")) {
      row.classList.toggle("current", row.dataset.evaluationId === state.watchId);
    }
  }

  async function loadHistory() {
    if (!state.key) return;
    stopHistoryPolling();
    try {
      const page = await api("/evaluations");
      const items = Array.isArray(page.items) ? page.items : [];
      state.history = { items, count: page.count };
      renderHistory(items, page.count);
      // Evaluations started elsewhere (another tab, the API) still move: look again soon.
      if (items.some((e) => isActive(e.status) && e.id !== state.watchId)) {
        state.historyTimer = setTimeout(loadHistory, HISTORY_POLL_MS);
      }
    } catch (err) {
      reportError(err);
    }
  }

  function headlineCell(evaluation) {
    const cell = el("td", { className: "num", "data-label": "ATE RMSE" });
    const summary = Array.isArray(evaluation.summary) ? evaluation.summary : [];
    if (!summary.length) {
      cell.textContent = "—";
      return cell;
    }
    const unit = lengthUnit(summary.map((s) => s.ate_rmse_m));
    if (summary.length === 1) {
      cell.dataset.valueM = String(summary[0].ate_rmse_m);
      cell.append(formatMetres(summary[0].ate_rmse_m, unit), ...verdictMark(summary[0].verdict));
      return cell;
    }
    for (const s of summary) {
      cell.append(el("div", {}, el("span", { className: "muted small", text: `${s.name} ` }),
        formatMetres(s.ate_rmse_m, unit), ...verdictMark(s.verdict)));
    }
    return cell;
  }

  /** The history's small badge of a verdict; nothing (not a "null") without a tolerance. */
  function verdictMark(verdict) {
    if (!verdict) return [];
    const badge = verdictBadge(verdict);
    badge.classList.add("tiny");
    return [" ", badge];
  }

  function renderHistory(items, count) {
    const body = $("history-body");
    body.replaceChildren();
    for (const evaluation of items) {
      const open = el("button", {
        type: "button", className: "secondary small", text: "Open",
        "aria-label": `Open evaluation ${evaluation.id}`,
        onclick: () => {
          watch(evaluation.id);
          $("current-card").scrollIntoView({ behavior: "smooth", block: "start" });
        },
      });
      body.append(el("tr", { dataset: { evaluationId: evaluation.id, status: evaluation.status } },
        el("td", { className: "nowrap", text: formatTime(evaluation.created_at) }),
        el("td", { className: "estimates-cell", "data-label": "Estimates", text: estimateNames(evaluation).join(", ") }),
        el("td", { "data-label": "Status" }, statusBadge(evaluation.status)),
        headlineCell(evaluation),
        el("td", { className: "actions" }, open)));
    }
    renderBaselineChoices(items);
    const empty = items.length === 0;
    setHidden($("history-table"), empty);
    setHidden($("history-empty"), !empty);
    if (typeof count === "number" && count > items.length) {
      body.append(el("tr", {}, el("td", { colspan: "5", className: "muted",
        text: `Showing the newest ${items.length} of ${count} evaluations.` })));
    }
    markHistoryRow();
  }

  /** Offer the succeeded evaluations of the history as the baseline (options.baseline). */
  function renderBaselineChoices(items) {
    const choices = items.filter((e) => e.status === "succeeded").map((e) => ({
      value: e.id, text: `${formatTime(e.created_at)} · ${estimateNames(e).join(", ")} (${e.id.slice(0, 8)})`,
    }));
    for (const select of document.querySelectorAll("#other-options-grid select.evaluation-choice")) {
      fillChoice(select, choices, NONE, NONE);
    }
  }

  // --- schedules ---------------------------------------------------------------------------

  async function loadSchedules() {
    if (!state.key) return;
    try {
      const page = await api("/schedules");
      state.schedules = Array.isArray(page.items) ? page.items : [];
      const runs = await Promise.all(state.schedules.map((schedule) =>
        api(`/schedules/${encodeURIComponent(schedule.id)}/runs?limit=1`)
          .then((r) => (r.items && r.items[0]) || null)
          .catch(() => null)));
      state.scheduleRuns = new Map(state.schedules.map((schedule, i) => [schedule.id, runs[i]]));
      renderSchedules();
      for (const [id, run] of state.scheduleRuns) {
        if (run && isActive(run.status) && !state.runTimers.has(id)) watchRun(id, run.id);
      }
    } catch (err) {
      reportError(err);
    }
  }

  function describeSelection(selection) {
    const parts = [];
    const tags = (selection && selection.tags) || [];
    if (tags.length) parts.push(`tagged ${tags.join(", ")}`);
    if (selection && selection.name_pattern) parts.push(`named ${selection.name_pattern}`);
    if (selection && selection.uploaded_within_days) parts.push(`uploaded in the last ${selection.uploaded_within_days} days`);
    return parts.length ? parts.join("; ") : "every recording";
  }

  function lastRunCell(run) {
    if (!run) return el("span", { className: "muted", text: "never run" });
    const rows = Array.isArray(run.rows) ? run.rows : [];
    const failed = rows.filter((r) => r.status === "failed").length;
    const facts = [formatTime(run.finished_at || run.started_at || run.created_at)];
    if (rows.length) facts.push(plural(rows.length, "recording", "recordings") + (failed ? `, ${failed} failed` : ""));
    if (isActive(run.status) && run.progress && run.progress.stage) facts.push(run.progress.stage);
    return el("span", {},
      statusBadge(run.status), " ",
      el("span", { className: "muted small", text: facts.join(" · ") }),
      run.error && run.error.detail ? el("div", { className: "error-text small", text: nameFields(run.error.detail) }) : null);
  }

  function renderSchedules() {
    const body = $("schedules-body");
    body.replaceChildren();
    for (const schedule of state.schedules) {
      const run = state.scheduleRuns.get(schedule.id) || null;
      const message = el("span", { className: "error-text small" });
      const summary = run && Array.isArray(run.artifacts)
        ? run.artifacts.find((a) => a.name === "summary.html") || run.artifacts[0] : null;
      const actions = el("div", { className: "schedule-actions" });
      const runButton = el("button", {
        type: "button", className: "secondary small", text: "Run now",
        disabled: Boolean(run && isActive(run.status)),
        onclick: () => runScheduleNow(schedule, runButton, message),
      });
      const pauseButton = el("button", {
        type: "button", className: "secondary small", text: schedule.paused ? "Resume" : "Pause",
        onclick: () => setSchedulePaused(schedule, !schedule.paused, pauseButton, message),
      });
      actions.append(runButton, pauseButton);
      if (summary) {
        const open = el("button", {
          type: "button", className: "primary small", text: "Open summary",
          dataset: { artifact: summary.name },
        });
        open.addEventListener("click", () => fetchArtifact(run, summary, true, open, message));
        actions.append(open);
      }
      const remove = el("button", {
        type: "button", className: "danger small", text: "Delete",
        "aria-label": `Delete the schedule ${schedule.name}`,
        onclick: () => deleteSchedule(schedule, remove, message),
      });
      actions.append(remove);
      body.append(el("tr", { dataset: { scheduleId: schedule.id, paused: String(schedule.paused) } },
        el("td", {}, el("strong", { text: schedule.name }),
          schedule.paused ? el("div", {}, el("span", { className: "status status-queued", text: "paused" })) : null),
        el("td", { className: "schedule-when", "data-label": "When" },
          el("code", { text: schedule.cron }), " ",
          el("span", { className: "muted small", text: schedule.timezone }),
          el("div", { className: "muted small", text: schedule.paused || !schedule.next_fire_at
            ? "does not fire while paused" : `next: ${formatTime(schedule.next_fire_at)}` })),
        el("td", { "data-label": "Recordings", text: describeSelection(schedule.selection) }),
        el("td", { "data-label": "Last run", className: "last-run" }, lastRunCell(run)),
        el("td", { className: "actions" }, actions, message)));
    }
    const empty = state.schedules.length === 0;
    setHidden($("schedules-table"), empty);
    setHidden($("schedules-empty"), !empty);
  }

  async function runScheduleNow(schedule, button, message) {
    message.textContent = "";
    button.disabled = true;
    try {
      const run = await api(`/schedules/${encodeURIComponent(schedule.id)}/run`, { method: "POST" });
      state.scheduleRuns.set(schedule.id, run);
      renderSchedules();
      if (isActive(run.status)) watchRun(schedule.id, run.id);
    } catch (err) {
      button.disabled = false;
      reportError(err, message);
    }
  }

  function watchRun(scheduleId, runId) {
    clearTimeout(state.runTimers.get(scheduleId));
    const tick = async () => {
      try {
        const run = await api(`/schedules/${encodeURIComponent(scheduleId)}/runs/${encodeURIComponent(runId)}`);
        state.scheduleRuns.set(scheduleId, run);
        renderSchedules();
        if (!isActive(run.status)) {
          state.runTimers.delete(scheduleId);
          loadHistory(); // the run's evaluations are listed with the others
          return;
        }
      } catch (err) {
        state.runTimers.delete(scheduleId);
        reportError(err);
        return;
      }
      state.runTimers.set(scheduleId, setTimeout(tick, POLL_MS));
    };
    state.runTimers.set(scheduleId, setTimeout(tick, POLL_MS));
  }

  function stopRunWatching() {
    for (const timer of state.runTimers.values()) clearTimeout(timer);
    state.runTimers.clear();
  }

  async function setSchedulePaused(schedule, paused, button, message) {
    message.textContent = "";
    button.disabled = true;
    try {
      await api(`/schedules/${encodeURIComponent(schedule.id)}`, { method: "PATCH", json: { paused } });
      await loadSchedules();
    } catch (err) {
      button.disabled = false;
      reportError(err, message);
    }
  }

  async function deleteSchedule(schedule, button, message) {
    if (!window.confirm(`Delete the schedule “${schedule.name}” and its runs? This cannot be undone.`)) return;
    button.disabled = true;
    try {
      await api(`/schedules/${encodeURIComponent(schedule.id)}`, { method: "DELETE" });
      clearTimeout(state.runTimers.get(schedule.id));
      state.runTimers.delete(schedule.id);
      await loadSchedules();
    } catch (err) {
      button.disabled = false;
      reportError(err, message);
    }
  }

  function readScheduleForm() {
    const name = $("sched-name").value.trim();
    if (!name) throw new Error("Name the schedule (e.g. Weekly level 2).");
    const cron = $("sched-cron").value.trim();
    if (!cron) throw new Error("When: write a cron expression, e.g. 0 7 * * mon (Mondays at 07:00).");
    const estimate = $("sched-estimate").value.trim();
    const estimateName = $("sched-estimate-name").value.trim();
    const reference = $("sched-reference").value.trim();
    const tags = $("sched-tags").value.split(",").map((t) => t.trim()).filter(Boolean);
    return {
      name,
      cron,
      timezone: $("sched-timezone").value.trim() || "UTC",
      selection: tags.length ? { tags } : {},
      template: {
        reference: { selector: reference || null },
        estimates: [{ selector: estimate || null, name: estimateName || null }],
        options: readOptions(),
      },
      // the API's default is both summaries; a server that cannot write PDFs makes the HTML
      ...(PDF_REPORTS ? {} : { produce: { summary_formats: ["summary.html"] } }),
    };
  }

  async function createSchedule(event) {
    event.preventDefault();
    const errorText = $("schedule-form-error");
    errorText.textContent = "";
    clearInvalid($("eval-form"));
    let body;
    try {
      body = readScheduleForm();
    } catch (err) {
      errorText.textContent = err.message;
      if (err.fields) markInvalid(err.fields);
      return;
    }
    const button = $("schedule-create-button");
    button.disabled = true;
    try {
      await api("/schedules", { method: "POST", json: body });
      $("schedule-form").reset();
      await loadSchedules();
    } catch (err) {
      reportError(err, errorText);
      if (err instanceof ApiError) markInvalid(err.fields);
    } finally {
      button.disabled = false;
    }
  }

  // --- card numbers ------------------------------------------------------------------------

  /** Number the shown cards 1, 2, 3… in page order: the numbers are not written in the HTML. */
  function numberSteps() {
    let n = 0;
    for (const card of document.querySelectorAll("#app > .card")) {
      const step = card.querySelector(":scope > h2 .step, :scope > .card-head > h2 .step");
      if (!step) continue;
      if (card.hidden) {
        step.textContent = "";
        continue;
      }
      n += 1;
      if (step.textContent !== String(n)) step.textContent = String(n);
    }
  }

  // --- start -------------------------------------------------------------------------------

  function init() {
    $("key-form").addEventListener("submit", (event) => {
      event.preventDefault();
      const key = $("key-input").value.trim().replace(/^Bearer\s+/i, "");
      if (!key) {
        showBanner("Paste the API key first.", "error");
        $("key-input").focus();
        return;
      }
      useKey(key);
    });
    $("key-forget").addEventListener("click", forgetKey);
    $("banner-close").addEventListener("click", hideBanner);
    $("file-input").addEventListener("change", (event) => {
      const files = Array.from(event.target.files || []);
      event.target.value = ""; // the same file can be chosen again
      if (files.length) enqueueUploads(files);
    });
    const drop = $("file-drop");
    for (const name of ["dragenter", "dragover"]) {
      drop.addEventListener(name, () => drop.classList.add("dragging"));
    }
    for (const name of ["dragleave", "drop"]) {
      drop.addEventListener(name, () => drop.classList.remove("dragging"));
    }
    $("upload-clear").addEventListener("click", clearFinishedUploads);
    $("datasets-refresh").addEventListener("click", loadDatasets);
    $("history-refresh").addEventListener("click", loadHistory);
    $("add-estimate").addEventListener("click", () => addEstimateRow().querySelector("select").focus());
    $("eval-form").addEventListener("submit", startEvaluation);
    $("schedule-form").addEventListener("submit", createSchedule);
    $("ranging-form").addEventListener("submit", startRanging);
    $("ranging-dims").addEventListener("change", updateTagHeight);
    $("schedules-refresh").addEventListener("click", loadSchedules);
    $("opt-device-dataset").addEventListener("change", renderDeviceLinks);
    renderFormatBoxes();
    renderOtherOptions();
    applyOptionDocs();
    numberSteps();
    // A card shown or hidden (the current evaluation's) renumbers the cards after it.
    new MutationObserver(numberSteps).observe($("app"), { attributes: true, attributeFilter: ["hidden"], subtree: true });
    try {
      $("sched-timezone").defaultValue = Intl.DateTimeFormat().resolvedOptions().timeZone || "UTC";
    } catch {
      // keep UTC
    }
    addEstimateRow();
    renderSourceSelects();

    state.key = readStoredKey();
    renderKeyState();
    if (state.key) loadAll();
    else $("key-input").focus();
  }

  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", init);
  else init();
})();
