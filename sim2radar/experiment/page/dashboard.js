// The sweep dashboard's script, inlined into the page by
// sim2radar.experiment.dashboard.page.render_html. render(data) fills every section from
// the JSON document in #dashboard-data; the live page (#dashboard-live: poll_ms > 0) polls
// data.json and calls render again when it changed. Table sort, filter and grouping state
// survive re-renders. Clicking a run's row opens its own view (#run=<id>; the live server
// also serves it at /run/<id>). window.dashboard (state) and window.dashboardExport are read
// by the browser tests (tests/experiment/test_dashboard_browser.py). esc, table and plot are
// common.js's (S2R), shared with the comparison page.
(function () {
"use strict";
const state = {data: null, text: null, sortCol: null, sortDir: 1, renders: 0,
  filter: {}, groupBy: "", shown: [], run: null, gapText: null};
window.dashboard = state;
const {$, esc, table, plot} = S2R;
function fmt(v, type) {
  if (v === null || v === undefined || v === "") return type === "text" ? "" : "—";
  switch (type) {
    case "pct": return (100 * v).toLocaleString("en", {maximumFractionDigits: 2}) + " %";
    case "ap": return Number(v).toFixed(2);
    case "ratio": return Number(v).toFixed(1) + ":1";
    case "int": return String(v);
    case "seconds": return v >= 3600 ? (v / 3600).toFixed(2) + " h" :
      v >= 60 ? (v / 60).toFixed(1) + " min" : Number(v).toFixed(1) + " s";
    case "key": return String(v).slice(0, 12);
    case "condition": return label(v);
    default: return String(v);
  }
}
function label(name) {
  const c = (state.data.conditions || []).find((x) => x.name === name);
  return c ? c.label : String(name);
}
function compare(a, b, type) {
  const na = a === null || a === undefined || a === "", nb = b === null || b === undefined ||
    b === "";
  if (na || nb) return na && nb ? 0 : na ? 1 : -1;   // empty cells last, either direction
  if (type === "text" || type === "key" || type === "condition")
    return state.sortDir * String(a).localeCompare(String(b));
  return state.sortDir * (a - b);
}
// the rows the filters let through, sorted, in group order when grouped
function visibleRuns() {
  const runs = state.data.runs, cols = runs.columns;
  let rows = runs.rows.filter((r) => runs.group_columns.every((i) => {
    const want = state.filter[cols[i].key];
    return want === undefined || want === "" || String(r[i]) === want;
  }));
  if (state.sortCol !== null && state.sortCol < cols.length) {
    const i = state.sortCol, t = cols[i].type;
    rows = rows.slice().sort((a, b) => compare(a[i], b[i], t));
  }
  const g = cols.findIndex((c) => c.key === state.groupBy);
  if (g >= 0) {  // stable: keeps the sort order within each group
    const keys = [...new Set(rows.map((r) => String(r[g])))].sort((a, b) =>
      cols[g].type === "condition" || cols[g].type === "text" ? a.localeCompare(b) : a - b);
    rows = keys.flatMap((k) => rows.filter((r) => String(r[g]) === k));
  }
  return {rows: rows, group: g};
}
function renderControls() {
  const runs = state.data.runs, cols = runs.columns;
  let out = "";
  for (const i of runs.group_columns) {
    const c = cols[i], cur = state.filter[c.key] || "";
    const values = [...new Set(runs.rows.map((r) => r[i]).filter((v) => v !== null))]
      .sort((a, b) => (typeof a === "number" ? a - b : String(a).localeCompare(String(b))));
    out += "<label>" + esc(c.label) + " <select id='filter-" + esc(c.key) + "' data-key='" +
      esc(c.key) + "'><option value=''>all</option>" + values.map((v) => "<option value='" +
      esc(v) + "'" + (String(v) === cur ? " selected" : "") + ">" + esc(fmt(v, c.type)) +
      "</option>").join("") + "</select></label>";
  }
  out += "<label>group by <select id='group-by'><option value=''>none</option>" +
    runs.group_columns.map((i) => "<option value='" + esc(cols[i].key) + "'" +
    (cols[i].key === state.groupBy ? " selected" : "") + ">" + esc(cols[i].label) +
    "</option>").join("") + "</select></label>" +
    "<button type=button id='download-csv'>download CSV</button>" +
    "<button type=button id='download-json'>download JSON</button>" +
    "<span class=muted id='runs-shown'></span>";
  $("runs-controls").innerHTML = out;
}
function renderRuns() {
  const runs = state.data.runs, cols = runs.columns;
  const head = cols.map((c, i) => "<th data-col=" + i + " title='sort by " + esc(c.label) +
    "' aria-sort=" + (state.sortCol === i ? (state.sortDir > 0 ? "ascending" : "descending") :
    "none") + ">" + esc(c.label) + "</th>").join("");
  const vis = visibleRuns(), rows = vis.rows;
  state.shown = rows;
  const ids = new Map(runs.rows.map((r, i) => [r, (runs.ids || [])[i]]));
  const statusCol = runs.status_column, metricCol = runs.metric_column;
  let body = "", last = null;
  for (const r of rows) {
    if (vis.group >= 0 && String(r[vis.group]) !== last) {
      last = String(r[vis.group]);
      const members = rows.filter((x) => String(x[vis.group]) === last);
      const vals = members.map((x) => x[metricCol]).filter((v) => v !== null);
      const mean = vals.length ? vals.reduce((a, b) => a + b, 0) / vals.length : null;
      body += "<tr class=group><td colspan=" + cols.length + ">" +
        esc(cols[vis.group].label) + " " + esc(fmt(r[vis.group], cols[vis.group].type)) +
        " · " + members.length + " run(s) · mean " + esc(cols[metricCol].label) + " " +
        (mean === null ? "—" : mean.toFixed(2)) + "</td></tr>";
    }
    const id = ids.get(r);
    body += "<tr class='run" + (r[statusCol] === "failed" ? " failed" : "") +
      (id !== undefined && id === state.run ? " selected" : "") + "'" +
      (id !== undefined ? " data-run='" + esc(id) + "' title='open this run'" : "") + ">" +
      r.map((v, i) => {
        const t = cols[i].type, title = t === "key" && v ? " title='" + esc(v) + "'" : "";
        const cls = cols[i].key === "error" ? " class=err" : (t !== "text" && t !== "key" &&
          t !== "condition" ? " class=num" : "");
        return "<td" + cls + title + ">" + esc(fmt(v, t)) + "</td>";
      }).join("") + "</tr>";
  }
  $("runs-table").innerHTML = "<thead><tr>" + head + "</tr></thead><tbody>" + body +
    "</tbody>";
  $("runs-empty").style.display = rows.length ? "none" : "block";
  const shown = $("runs-shown");
  if (shown) shown.textContent = rows.length + " of " + runs.rows.length + " runs shown";
}
// downloads of the rows shown (raw values, every column), built here: the page fetches nothing
function csvCell(v, type) {
  if (v === null || v === undefined) return "";
  let s = typeof v === "object" ? JSON.stringify(v) : String(v);
  if (type === "text" && /^[=+\-@\t\r]/.test(s)) s = "'" + s;  // no formulas in spreadsheets
  return /[",\r\n]/.test(s) ? '"' + s.replace(/"/g, '""') + '"' : s;
}
function runsCsv(rows) {
  const cols = state.data.runs.columns;
  return [cols.map((c) => csvCell(c.key, "key")).join(",")].concat(rows.map((r) =>
    r.map((v, i) => csvCell(v, cols[i].type)).join(","))).join("\r\n") + "\r\n";
}
function runsJson(rows) {
  const cols = state.data.runs.columns;
  return JSON.stringify(rows.map((r) => Object.fromEntries(cols.map((c, i) => [c.key, r[i]]))),
    null, 1);
}
function download(text, type, ext) {
  const url = URL.createObjectURL(new Blob([text], {type: type}));
  const a = document.createElement("a");
  a.href = url; a.download = "sweep-" + state.data.name + "-runs." + ext;
  document.body.appendChild(a); a.click(); a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 1000);
}
window.dashboardExport = {csv: () => runsCsv(state.shown), json: () => runsJson(state.shown)};
function renderProgress(p) {
  $("run-count").textContent = p.finished;
  $("run-total").textContent = p.total;
  $("run-state").textContent = p.state;
  const bar = $("run-progress");
  bar.max = Math.max(p.total, 1); bar.value = p.finished;
  $("run-counts").innerHTML = "<span>computed: <b id=count-ok>" + p.ok + "</b></span>" +
    "<span>cached: <b id=count-skipped>" + p.skipped + "</b></span>" +
    "<span>failed: <b id=count-failed" + (p.failed ? " style='color:#c0392b'" : "") + ">" +
    p.failed + "</b></span>" + (p.updated_at ? "<span class=muted>progress.json " +
    esc(p.updated_at) + "</span>" : "");
  $("run-running").innerHTML = (p.pretrainings_total ? "<span id=pretrain-progress>" +
    "pre-trainings finished: <b>" + p.pretrainings_finished + "</b> of " +
    p.pretrainings_total + "</span> " : "") +
    (p.running.length ? "running: " + p.running.map(esc).join(", ") : "");
}
function renderDatasets(d) {
  let out = "";
  if (d.datasets.length) {
    out += "<h3>Datasets of the sweep</h3>" + table(["role", "domain", "frames", "splits",
      "path", "content key"], d.datasets.map((x) => [x.role, x.domain, x.frames, x.splits,
      x.path, x.key]), (i) => i === 2);
  }
  if (d.generation) {
    out += "<h3>Dataset generation</h3>" + table(["dataset", "role", "scenes ok",
      "scenes failed", "scenes skipped", "frames", "points / frame", "labels / frame"],
      d.generation.map((x) => [x.name, x.role, x.scenes_ok, x.scenes_failed, x.scenes_skipped,
      x.frames, x.points_per_frame, x.labels_per_frame]), (i) => i >= 2);
  } else {
    out += "<p class=muted>No generation.json in the sweep folder: dataset generation status " +
      "not recorded.</p>";
  }
  $("datasets").innerHTML = out;
}
// the gap report's figures, drawn from gap.json's numbers; PNGs only where it has none.
// Rebuilt only when the report changed (a live re-render keeps their zoom)
function renderGap(g) {
  const text = JSON.stringify(g);
  if (text === state.gapText) return;
  state.gapText = text;
  for (const el of document.querySelectorAll("#gap .plot")) Plotly.purge(el);
  if (!g) {
    $("gap").innerHTML = "<p class=muted>No sim–real gap report in this sweep folder " +
      "(gap/gap.json): <code>sim2radar gap SIM REAL --out &lt;sweep&gt;/gap</code> writes one.</p>";
    return;
  }
  let out = table(["", "sim", "real"], g.rows, (i) => i > 0) + "<br>" +
    table(["", ""], g.facts, null);
  out += (g.figures || []).map((f) => "<div class='card gap-plot'><div id='gap-plot-" +
    esc(f.name) + "' class=plot></div><p class=muted>" + esc(f.title) + "</p></div>").join("");
  if ((g.images || []).length) {
    out += "<p class=muted id=gap-image-note>" + esc(g.image_note || "") + "</p>" +
      "<div class=gap-figs>" + g.images.map((f) => "<figure><img alt='" + esc(f.name) +
      "' src='" + esc(f.uri) + "'><figcaption>" + esc(f.title) + " (PNG)</figcaption></figure>")
      .join("") + "</div>";
  }
  $("gap").innerHTML = out;
  for (const f of g.figures || []) plot("gap-plot-" + f.name, f.figure);
}
function renderProvenance(p) {
  if (!p) {
    $("provenance").innerHTML = "<p class=muted>sweep.json not found: no provenance.</p>";
    return;
  }
  let out = "<p>created " + esc(p.created_at || "—") + (p.git ? " · git " + esc(p.git) : "") +
    "</p>";
  if (p.settings_digest) out += "<p>settings (digest " + esc(p.settings_digest) +
    ") fixed at " + esc(p.settings_fixed_at || "—") +
    ", before any run; a rerun with changed settings is refused</p>";
  const code = Object.entries(p.code || {});
  if (code.length) out += "<h3>Code</h3>" + table(["", ""], code, null);
  const ds = Object.entries(p.datasets || {});
  if (ds.length) out += "<h3>Datasets</h3>" + table(["role", "path", "content key", "domain"],
    ds.map(([role, d]) => [role, d.path || "—", d.key || "—", d.domain || "—"]), null);
  out += "<h3>Package versions</h3>" + table(["package", "version"],
    Object.entries(p.versions || {}), null);
  for (const [name, text] of Object.entries(p.configs || {})) {
    out += "<details><summary>detector config: " + esc(name) + "</summary><pre>" + esc(text) +
      "</pre></details>";
  }
  out += "<details><summary>experiment profile</summary><pre>" + esc(p.profile) +
    "</pre></details>";
  if (p.intensity_match) out += "<details><summary>intensity matching</summary><pre>" +
    esc(p.intensity_match) + "</pre></details>";
  $("provenance").innerHTML = out;
}
// the pre-registered primary endpoint: hidden without a pooled endpoint (an older stats.json)
function renderPrimary(p) {
  const rows = p && p.rows ? p.rows : [];
  $("primary-section").style.display = rows.length ? "block" : "none";
  $("primary-sentence").textContent = rows.length ? p.sentence || "" : "";
  $("primary-table").innerHTML = rows.length ? table(p.columns, rows,
    (i) => (p.numeric || [])[i]) : "";
  $("primary-note").textContent = rows.length ? p.note || "" : "";
}
// the pre-trainings' checks and loss curves; "No pre-training recorded." without any
function renderPretrainings(p) {
  const has = !!(p && p.figures && p.figures.check);
  $("pretrain-empty").style.display = has ? "none" : "block";
  for (const id of ["pretrain-note", "pretrain-summary", "pretrain-check-card",
    "pretrain-loss-card", "pretrain-details"]) $(id).style.display = has ? "" : "none";
  if (!has) {
    $("pretrain-summary").innerHTML = "";
    $("pretrain-rows").innerHTML = "";
    plot("plot-pretrain-check", null);
    plot("plot-pretrain-loss", null);
    return;
  }
  $("pretrain-note").textContent = p.note || "";
  $("pretrain-summary").innerHTML = p.summary.rows.length ? table(p.summary.columns,
    p.summary.rows, (i) => p.summary.numeric[i]) : "";
  plot("plot-pretrain-check", p.figures.check);
  plot("plot-pretrain-loss", p.figures.loss);
  $("pretrain-details-summary").textContent = "Every pre-training (" + p.n + ", " +
    p.n_failed + " failed)";
  $("pretrain-rows").innerHTML = table(p.table.columns, p.table.rows,
    (i) => p.table.numeric[i]);
}
// one run's own view (#run-section): its settings, learning curve, final APs, its
// pre-training's check and its folder, from run_views; hidden while no run is chosen
function renderRun() {
  const sec = $("run-section"), id = state.run;
  const views = (state.data.run_views || {}).views || {};
  if (id === null) {
    sec.hidden = true;
    plot("plot-run", null);
    return;
  }
  sec.hidden = false;
  const v = views[id];
  $("run-id").textContent = id;
  if (!v) {
    $("run-title").textContent = "Run not found";
    $("run-body").hidden = true;
    $("run-missing").hidden = false;
    $("run-missing").textContent = "No run " + id + " in this sweep" +
      (live.poll_ms > 0 ? " (yet: it appears here when it finishes)." : ".");
    plot("plot-run", null);
    return;
  }
  $("run-missing").hidden = true;
  $("run-body").hidden = false;
  $("run-title").textContent = "Run: " + v.title;
  $("run-status").textContent = v.status;
  $("run-status").className = "badge " + v.status;
  $("run-error").textContent = v.error;
  $("run-error").hidden = !v.error;
  $("run-settings").innerHTML = table(["setting", "value"], v.settings, null);
  $("run-aps").innerHTML = table(v.aps.columns, v.aps.rows, (i) => v.aps.numeric[i]);
  $("run-delta").textContent = v.delta || "";
  const layout = Object.assign({}, state.data.run_views.layout, {uirevision: id});
  if (!v.pretraining) {  // the third panel says why it is empty
    layout.annotations = (layout.annotations || []).concat([{text: "no pre-training",
      xref: "x3 domain", yref: "y3 domain", x: 0.5, y: 0.5, showarrow: false,
      font: {size: 14, color: "#777"}}]);
  }
  plot("plot-run", {data: v.traces, layout: layout});
  $("run-curve-note").textContent = v.curve_note || "";
  $("run-pretrain-note").textContent = v.pretraining ? "Found " + v.pretraining.how + "." :
    "Pre-training: " + v.pretraining_note + ".";
  $("run-pretrain").innerHTML = v.pretraining ? table(["check", "value"], v.pretraining.rows,
    null) : "";
  $("run-folder").textContent = v.folder || "—";
  $("run-folder-path").textContent = v.folder_path || "—";
  $("run-checkpoint").textContent = v.checkpoint || "—";
}
// the run named by the address: #run=<id>, else the live server's /run/<id>
function runFromAddress() {
  const h = location.hash.match(/^#run=(.+)$/);
  if (h) return decodeURIComponent(h[1]);
  const p = location.pathname.match(/\/run\/([^/]+)$/);
  return p && live.poll_ms > 0 ? decodeURIComponent(p[1]) : null;
}
function openRun(id, scroll) {
  state.run = id;
  renderRuns();
  renderRun();
  if (scroll && id !== null) $("run-section").scrollIntoView({block: "start"});
}
function render(d) {
  state.data = d;
  document.title = "sim2radar sweep " + d.name;
  $("title").textContent = "Sweep " + d.name;
  $("subtitle").textContent = [d.profile ? "profile " + d.profile : null, "metric " +
    d.metric_label, d.created_at ? "created " + d.created_at : null, d.folder]
    .filter(Boolean).join(" · ");
  const b = $("banner");
  b.className = d.banner.kind; b.textContent = d.banner.text;
  const err = $("error");
  err.style.display = d.error ? "block" : "none"; err.textContent = d.error || "";
  renderProgress(d.progress);
  renderPrimary(d.primary);
  plot("plot-ap", d.figures.ap);
  plot("plot-delta", d.figures.delta);
  plot("plot-curves", d.figures.curves);
  filterCurves();
  $("summary").innerHTML = d.summary.rows.length ? table(d.summary.columns, d.summary.rows,
    (i) => (d.summary.numeric || [])[i]) : "<p class=muted>No comparison yet.</p>";
  const sentences = d.summary.sentences || [];
  $("power-summary").innerHTML = sentences.map((x) => "<p>" + esc(x) + "</p>").join("");
  $("power-summary").style.display = sentences.length ? "block" : "none";
  $("summary-note").textContent = d.summary.interval_note || "";
  renderPretrainings(d.pretrainings);
  $("notes").innerHTML = d.notes.map((n) => "<li>" + esc(n) + "</li>").join("");
  $("stats-source").textContent = "statistics: " + d.stats_source;
  renderControls();
  renderRuns();
  renderRun();
  renderDatasets(d);
  renderGap(d.gap);
  renderProvenance(d.provenance);
  $("warnings").innerHTML = d.warnings.map((w) => "<li>" + esc(w) + "</li>").join("");
  $("warnings-section").style.display = d.warnings.length ? "block" : "none";
  state.renders += 1;
}
// the learning curves show what the runs table's filters let through (condition, fraction;
// a run's own curve also its trial)
function filterCurves() {
  const el = $("plot-curves");
  if (!el || !el.data) return;
  const f = state.filter;
  const ok = (key, value) => f[key] === undefined || f[key] === "" ||
    String(value) === f[key];
  const vis = el.data.map((t) => {
    const m = t.meta || {};
    if (m.condition === undefined) return true;
    return ok("condition", m.condition) && ok("fraction", m.fraction) &&
      (m.trial === undefined || ok("trial", m.trial));
  });
  Plotly.restyle(el, {visible: vis});
}
$("runs-controls").addEventListener("change", (e) => {
  const el = e.target;
  if (el.id === "group-by") state.groupBy = el.value;
  else if (el.dataset && el.dataset.key) state.filter[el.dataset.key] = el.value;
  renderRuns();
  filterCurves();
});
$("runs-controls").addEventListener("click", (e) => {
  if (e.target.id === "download-csv") download(runsCsv(state.shown), "text/csv", "csv");
  if (e.target.id === "download-json") download(runsJson(state.shown), "application/json",
    "json");
});
$("runs-table").addEventListener("click", (e) => {
  const row = e.target.closest("tr[data-run]");
  if (row) {  // the address names the run: a link to it, and the back button closes it
    const hash = "#run=" + encodeURIComponent(row.dataset.run);
    if (location.hash === hash) openRun(row.dataset.run, true);
    else location.hash = hash;
    return;
  }
  const th = e.target.closest("th[data-col]");
  if (!th) return;
  const i = Number(th.dataset.col);
  state.sortDir = state.sortCol === i ? -state.sortDir : 1;
  state.sortCol = i;
  renderRuns();
});
$("run-close").addEventListener("click", () => {
  if (location.hash) history.replaceState(null, "", location.pathname + location.search);
  openRun(null, false);
});
window.addEventListener("hashchange", () => openRun(runFromAddress(), true));
const live = JSON.parse($("dashboard-live").textContent);
const initial = $("dashboard-data").textContent;
state.text = initial;
state.run = runFromAddress();
render(JSON.parse(initial));
if (state.run !== null) $("run-section").scrollIntoView({block: "start"});
if (live.poll_ms > 0) {
  const status = $("live-status");
  async function poll() {
    try {
      const r = await fetch(live.data_url, {cache: "no-store"});
      const text = await r.text();
      if (!r.ok) {
        let msg = text;
        try { msg = JSON.parse(text).error; } catch (e) { /* plain text */ }
        $("error").style.display = "block"; $("error").textContent = msg;
      } else {
        if (text !== state.text) { state.text = text; render(JSON.parse(text)); }
        else { $("error").style.display = state.data.error ? "block" : "none"; }
        status.textContent = "live · checked " + new Date().toLocaleTimeString() +
          " · every " + live.poll_ms / 1000 + " s";
      }
    } catch (e) {
      status.textContent = "live · server unreachable at " + new Date().toLocaleTimeString() +
        "; retrying";
    }
    setTimeout(poll, live.poll_ms);
  }
  setTimeout(poll, live.poll_ms);
}
})();
