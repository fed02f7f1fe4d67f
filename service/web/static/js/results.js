// The results of a succeeded job: the report as a readable table, downloads, the spectrum.

import { apiFetch } from "./api.js";
import { drawSpectrum } from "./plot.js";
import { $, fillTable, filenameFrom, fmt, saveBlob, seconds } from "./ui.js";

export function showReport(report) {
  const t = report.timings || {};
  const rows = [
    ["λ", fmt(report.lambda, 6), "φ(λ)", fmt(report.phi, 6)],
    ["τ", fmt(report.tau, 6), "relative error |φ − τ| / τ", fmt(report.relative_error, 3)],
    ["converged", String(report.converged), "iterations", fmt(report.iterations)],
    ["factorizations", fmt(report.factorizations), "solver", report.solver || "–"],
    ["RMS displacement", fmt(report.rms_displacement), "max displacement", fmt(report.max_displacement)],
    ["points", fmt(report.n_points), "kind / dimension", `${report.kind} / ${report.dimension}-D`],
    ["Laplacian", report.laplacian || "–", "weights", report.weights || "–"],
    ["fixed points", fmt(report.n_fixed), "volume scale", fmt(report.volume_scale)],
  ];
  const keys = Object.keys(t).filter((k) => k !== "total");
  for (let i = 0; i < keys.length; i += 2) {
    const row = [`time: ${keys[i]}`, seconds(t[keys[i]])];
    if (keys[i + 1]) row.push(`time: ${keys[i + 1]}`, seconds(t[keys[i + 1]]));
    rows.push(row);
  }
  if (t.total !== undefined) rows.push(["time: total (smoothing)", seconds(t.total)]);
  for (const w of report.warnings || []) rows.push(["warning", w]);
  fillTable($("#report-table"), rows);
  const gamma = report.spectrum?.gamma;
  $("#spectrum-figure").hidden = !gamma;
  if (gamma) drawSpectrum($("#spectrum-plot"), gamma);
}

export function clearReport() {
  $("#report-table").replaceChildren();
  $("#spectrum-figure").hidden = true;
  $("#download-result").disabled = true;
  $("#download-report").disabled = true;
}

/** Enable the download buttons for `job` (a succeeded Job). */
export function enableDownloads(job) {
  const select = $("#download-format");
  const input = job.input_format ?? job.format;
  if (input && [...select.options].some((o) => o.value === input)) select.value = input;
  $("#download-result").disabled = false;
  $("#download-report").disabled = false;
  $("#download-result").onclick = async () => {
    const fmtName = select.value;
    const response = await apiFetch(`${job.links.result}?output_format=${encodeURIComponent(fmtName)}`);
    saveBlob(await response.blob(), filenameFrom(response, `result.${fmtName}`));
  };
  $("#download-report").onclick = async () => {
    const response = await apiFetch(job.links.report);
    const stem = (job.filename || job.id).replace(/\.[^.]*$/, "");
    saveBlob(await response.blob(), `${stem}.report.json`);
  };
}
