// loceval browser page: upload recordings, start evaluations, watch them, fetch the results.
// Plain ES2020, no libraries. Every text that comes from the server is set with textContent.
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
  const ALL_ARTIFACTS = [
    "report.html", "report.pdf", "result.json", "errors.csv",
    "paths.dxf", "paths.3dm", "paths.3dm.json", "paths.glb",
  ];
  const OPENED_IN_TAB = new Set(["report.html", "report.pdf"]);

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
  function formatMetres(m) {
    return typeof m === "number" && Number.isFinite(m) ? `${m.toFixed(3)} m` : "—";
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
    state.sources.clear();
    renderSourceSelects();
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
    constructor(status, message) {
      super(message);
      this.status = status;
    }
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
      if (typeof detail === "string" && detail) return detail;
      if (Array.isArray(detail) && detail.length) {
        return detail
          .map((d) => {
            if (!d || typeof d !== "object") return String(d);
            const where = Array.isArray(d.loc) ? d.loc.filter((p) => p !== "body").join(".") : "";
            return where ? `${where}: ${d.msg}` : String(d.msg);
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
      throw new ApiError(response.status, problemText(response.status, response.statusText, text));
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
      node, cancelled: false, xhr: null,
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
        setHidden(cancel, !["waiting", "uploading"].includes(name));
      },
    };
    cancel.addEventListener("click", () => {
      item.cancelled = true;
      if (item.xhr) item.xhr.abort();
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

  function upload({ file, tags, item }) {
    return new Promise((resolve) => {
      const xhr = new XMLHttpRequest();
      item.xhr = xhr;
      item.setState("uploading", "Uploading… 0%");
      updateClearButton();
      xhr.open("POST", `${API}/datasets`);
      xhr.setRequestHeader("Authorization", `Bearer ${state.key}`);
      xhr.setRequestHeader("Accept", "application/json");
      xhr.upload.onprogress = (event) => {
        if (!event.lengthComputable || !event.total) return;
        const fraction = event.loaded / event.total;
        item.setProgress(fraction);
        item.setState("uploading", `Uploading… ${Math.floor(fraction * 100)}%`);
      };
      xhr.upload.onload = () => {
        item.setProgress(1);
        item.setState("processing", "Reading the recording on the server…");
      };
      xhr.onload = () => {
        const { status } = xhr;
        if (status !== 401) state.keyVerified = true;
        if (status === 200 || status === 201) {
          item.setProgress(1);
          let dataset = null;
          try {
            dataset = JSON.parse(xhr.responseText);
          } catch {
            dataset = null;
          }
          const what = dataset ? describeDataset(dataset) : "";
          if (status === 200) {
            const name = dataset && dataset.name ? ` as “${dataset.name}”` : "";
            item.setState("duplicate", "Already uploaded", `These exact bytes were uploaded before${name}. ${what}`.trim());
          } else {
            item.setState("done", "Uploaded", what);
          }
          scheduleDatasetsReload();
        } else if (status === 401) {
          item.setState("error", "Not uploaded", UNAUTHORIZED);
          onUnauthorized();
        } else {
          item.setState("error", "Not uploaded", problemText(status, xhr.statusText, xhr.responseText));
        }
        resolve();
      };
      xhr.onerror = () => {
        item.setState("error", "Not uploaded",
          "The connection broke during the upload. The server may have refused a file this large, or it is not reachable.");
        resolve();
      };
      xhr.onabort = () => {
        item.setState("cancelled", "Cancelled");
        resolve();
      };
      const form = new FormData();
      form.append("file", file, file.name);
      if (tags) form.append("tags", tags);
      xhr.send(form);
    });
  }

  function describeDataset(dataset) {
    const sources = (dataset.inspection && dataset.inspection.sources) || [];
    const kind = dataset.kind ? `${dataset.kind}, ` : "";
    return `${kind}${plural(sources.length, "trajectory source", "trajectory sources")}.`;
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
        : el("span", { className: "muted", text: dataset.kind === "urdf" ? "No trajectory (device description)" : "No trajectory found" });
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
      if (!value) {
        if (name) throw new Error(`Choose the source of the estimate named “${name}”.`);
        continue;
      }
      estimates.push({ ...parseSource(value), name: name || null });
    }
    if (!estimates.length) throw new Error("Choose at least one estimate trajectory.");
    const options = {
      align: $("opt-align").value,
      association: $("opt-association").value,
      units: $("opt-units").value,
      rpe_unit: $("opt-rpe-unit").value,
    };
    const tolerance = $("opt-tolerance").value.replace(/\s+/g, "").replace(/%$/, "");
    if (tolerance) {
      if (!/^\d*\.?\d+@\d*\.?\d+$/.test(tolerance)) {
        throw new Error("Write the tolerance as metres@percent, e.g. 0.10@95 (95 % of poses within 0.10 m).");
      }
      options.tolerance = tolerance;
    }
    const number = (id, label, { positive = false } = {}) => {
      const text = $(id).value.trim();
      if (!text) return undefined;
      const value = Number(text);
      if (!Number.isFinite(value) || (positive && value <= 0)) {
        throw new Error(`${label} must be a${positive ? " positive" : ""} number.`);
      }
      return value;
    };
    const timeOffset = number("opt-time-offset", "The time offset");
    if (timeOffset !== undefined) options.time_offset_s = timeOffset;
    const maxGap = number("opt-max-gap", "The longest gap", { positive: true });
    if (maxGap !== undefined) options.max_gap_s = maxGap;
    const maxDt = number("opt-max-dt", "The nearest max Δt", { positive: true });
    if (maxDt !== undefined) options.max_dt_s = maxDt;
    const alignFirst = $("opt-align-first").value.replace(/\s+/g, "");
    if (alignFirst) {
      if (!/^(\d+|\d*\.?\d+s)$/.test(alignFirst)) {
        throw new Error("Align on the first: write a number of poses (50) or seconds (10s).");
      }
      options.align_first = alignFirst;
    }
    if ($("opt-stamp").value !== "header") options.stamp = $("opt-stamp").value;
    const delta = $("opt-rpe-delta").value.trim();
    if (delta) {
      const number = Number(delta);
      if (!Number.isFinite(number) || number <= 0) throw new Error("The RPE delta must be a positive number.");
      options.rpe_delta = number;
    }
    return { reference: { ...parseSource(reference), name: null }, estimates, options };
  }

  async function startEvaluation(event) {
    event.preventDefault();
    const errorText = $("eval-form-error");
    errorText.textContent = "";
    let body;
    try {
      body = readForm();
    } catch (err) {
      errorText.textContent = err.message;
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
    } finally {
      button.disabled = false;
    }
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
    else if (status === "running") stage = `${capitalize(stage || "working")}… ${pct}%`.replace(/……/, "…");
    else if (status === "succeeded") stage = "Finished.";
    else if (status === "failed") stage = stage && stage !== "failed" ? `Failed while ${stage}.` : "";
    $("current-stage").textContent = stage;

    if (status === "failed") {
      const problem = evaluation.error || {};
      showProblem(problem.detail || problem.title || "No reason was given.", "The evaluation failed:");
    } else {
      setHidden($("current-error"), true);
    }

    if (status === "succeeded") {
      renderSummary(evaluation);
      renderArtifacts(evaluation);
      setHidden($("current-result"), false);
    } else {
      setHidden($("current-result"), true);
    }
  }

  function verdictBadge(verdict) {
    if (verdict === "pass") return el("span", { className: "verdict verdict-pass", text: "PASS" });
    if (verdict === "fail") return el("span", { className: "verdict verdict-fail", text: "FAIL" });
    return el("span", { className: "verdict verdict-none", text: "no tolerance", title: "Set a tolerance to get a pass/fail verdict" });
  }

  function renderSummary(evaluation) {
    const body = $("summary-body");
    body.replaceChildren();
    for (const row of evaluation.summary || []) {
      body.append(el("tr", {},
        el("th", { scope: "row", className: "name", text: row.name }),
        el("td", { className: "num ate", "data-label": "ATE RMSE", dataset: { valueM: String(row.ate_rmse_m) }, text: formatMetres(row.ate_rmse_m) }),
        el("td", { className: "num", "data-label": "RPE RMSE", text: formatMetres(row.rpe_rmse_m) }),
        el("td", { className: "num", "data-label": "Matched", text: typeof row.matched === "number" ? row.matched.toLocaleString() : "—" }),
        el("td", { "data-label": "Verdict" }, verdictBadge(row.verdict))));
    }
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
      const rank = (x) => (ALL_ARTIFACTS.indexOf(x.name) + 1 || 99);
      return rank(a) - rank(b) || a.name.localeCompare(b.name);
    });
    if (!artifacts.length) {
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
        const link = el("a", { href: url, download: artifact.name, hidden: true });
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
    if (summary.length === 1) {
      cell.dataset.valueM = String(summary[0].ate_rmse_m);
      cell.append(formatMetres(summary[0].ate_rmse_m), " ", verdictMark(summary[0].verdict));
      return cell;
    }
    for (const s of summary) {
      cell.append(el("div", {}, el("span", { className: "muted small", text: `${s.name} ` }),
        formatMetres(s.ate_rmse_m), " ", verdictMark(s.verdict)));
    }
    return cell;
  }

  function verdictMark(verdict) {
    if (verdict === "pass") return el("span", { className: "verdict verdict-pass tiny", text: "PASS" });
    if (verdict === "fail") return el("span", { className: "verdict verdict-fail tiny", text: "FAIL" });
    return null;
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
    const empty = items.length === 0;
    setHidden($("history-table"), empty);
    setHidden($("history-empty"), !empty);
    if (typeof count === "number" && count > items.length) {
      body.append(el("tr", {}, el("td", { colspan: "5", className: "muted",
        text: `Showing the newest ${items.length} of ${count} evaluations.` })));
    }
    markHistoryRow();
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
