// The comparison page's script, inlined by
// sim2radar.experiment.dashboard.page.render_compare_html: render(data) fills every section
// from the JSON document in #compare-data (compare_data). window.comparison (the data, and
// renders) is read by the browser tests. esc, table and plot are common.js's (S2R).
(function () {
"use strict";
const {$, esc, table, plot} = S2R;
const state = {data: null, renders: 0};
window.comparison = state;
//: characters of a setting's value shown in its cell; the cell's tooltip holds all of it
const VALUE_CHARS = 160;
function short(v) {
  const s = String(v);
  return s.length <= VALUE_CHARS ? s : s.slice(0, VALUE_CHARS - 1) + "…";
}
function renderSweeps(d) {
  $("sweeps").innerHTML = ["a", "b"].map((k) => {
    const s = d[k];
    return "<div class='card sweep' id='sweep-" + k + "'><b>" + esc(d.names[k]) + "</b>" +
      (d.names[k] === k.toUpperCase() ? " " + esc(s.name) : "") + "<br>" +
      "<code>" + esc(s.folder) + "</code><br>" + [s.profile ? "profile " + s.profile : null,
        s.created_at ? "created " + s.created_at : null, s.runs + " runs (" + s.failed +
        " failed)", s.git ? "git " + s.git : null].filter(Boolean).map(esc).join(" · ") +
      "<div class='banner " + esc(s.banner.kind) + "'>" + esc(s.banner.text) + "</div></div>";
  }).join("");
}
function renderOnly(only, names) {
  const parts = ["a", "b"].map((k) => {
    const o = only[k], items = [];
    if (o.conditions.length) items.push("conditions: " + o.conditions.join(", "));
    if (o.fractions.length) items.push("fractions: " + o.fractions.join(", "));
    if (o.cells.length) items.push("cells: " + o.cells.join("; "));
    return "<li id='only-" + k + "'><b>only in " + esc(names[k]) + "</b>: " +
      (items.length ? esc(items.join(" · ")) : "nothing") + "</li>";
  });
  $("only").innerHTML = "<ul>" + parts.join("") + "</ul>";
}
function renderSettings(s, names) {
  $("settings-note").textContent = s.note;
  if (!s.rows.length) { $("settings").innerHTML = ""; return; }
  const head = "<tr><th>group</th><th>setting</th><th>" + esc(names.a) + "</th><th>" +
    esc(names.b) + "</th></tr>";
  const body = s.rows.map((r) => "<tr><td>" + esc(r[0]) + "</td><td><code>" + esc(r[1]) +
    "</code></td>" + r.slice(2).map((v) => "<td title='" + esc(v) + "'><code>" +
    esc(short(v)) + "</code></td>").join("") + "</tr>").join("");
  $("settings").innerHTML = "<table id=settings-table><thead>" + head + "</thead><tbody>" +
    body + "</tbody></table>";
}
function render(d) {
  state.data = d;
  $("subtitle").textContent = "metric " + d.metric_label + " · intervals " + d.level +
    " · A is the reference";
  renderSweeps(d);
  plot("plot-ap", d.figures.ap);
  plot("plot-delta", d.figures.delta);
  $("ap-table").innerHTML = d.table.rows.length ? table(d.table.columns, d.table.rows,
    (i) => d.table.numeric[i]) : "<p class=muted>No condition and fraction that both " +
    "sweeps ran.</p>";
  $("delta-table").innerHTML = d.delta_table.rows.length ? table(d.delta_table.columns,
    d.delta_table.rows, (i) => d.delta_table.numeric[i]) : "<p class=muted>No condition " +
    "besides the baseline that both sweeps ran at the same fraction.</p>";
  $("notes").innerHTML = d.notes.map((n) => "<li>" + esc(n) + "</li>").join("");
  renderOnly(d.only, d.names);
  renderSettings(d.settings, d.names);
  $("warnings").innerHTML = d.warnings.map((w) => "<li>" + esc(w) + "</li>").join("");
  $("warnings-section").style.display = d.warnings.length ? "block" : "none";
  state.renders += 1;
}
render(JSON.parse($("compare-data").textContent));
})();
