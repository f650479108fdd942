// Helpers shared by the sweep dashboard (dashboard.js) and the comparison page (compare.js),
// inlined before them by sim2radar.experiment.dashboard.page: S2R.$ (element by id), S2R.esc
// (HTML-escape a value), S2R.table (an HTML table of escaped cells), S2R.plot (draw a
// {data, layout} Plotly figure into an element, or clear it).
const S2R = (function () {
"use strict";
const CONFIG = {responsive: true, displaylogo: false};
const $ = (id) => document.getElementById(id);
function esc(v) {
  return String(v).replace(/[&<>"']/g, (c) => ({"&": "&amp;", "<": "&lt;", ">": "&gt;",
    '"': "&quot;", "'": "&#39;"}[c]));
}
function table(columns, rows, numeric) {  // numeric: (column index) -> right-align
  const head = "<tr>" + columns.map((c) => "<th>" + esc(c) + "</th>").join("") + "</tr>";
  const body = rows.map((r) => "<tr>" + r.map((v, i) =>
    "<td" + (numeric && numeric(i) ? " class=num" : "") + ">" + esc(v === null ||
      v === undefined ? "—" : v) + "</td>").join("") + "</tr>").join("");
  return "<table><thead>" + head + "</thead><tbody>" + body + "</tbody></table>";
}
function plot(id, fig) {
  if (!fig) { Plotly.purge($(id)); $(id).innerHTML = ""; return; }  // purge: no stale state
  Plotly.react($(id), fig.data, fig.layout, CONFIG);
}
return {$: $, esc: esc, table: table, plot: plot};
})();
