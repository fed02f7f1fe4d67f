// The results of a succeeded job: the report as a readable table, downloads, the spectrum.

import { apiFetch, ProblemError } from "./api.js";
import { drawSpectrum } from "./plot.js";
import { $, clearErrors, fillTable, filenameFrom, fmt, saveBlob, seconds, showProblem } from "./ui.js";

export function showReport(report) {
  const t = report.timings || {};
  const rows = [
    ["λ", fmt(report.lambda, 6), "φ(λ)", fmt(report.phi, 6)],
    ["τ", fmt(report.tau, 6), "relative error |φ − τ| / τ", fmt(report.relative_error, 3)],
    ["converged", String(report.converged), "iterations", fmt(report.iterations)],
    ["factorizations", fmt(report.factorizations), "solver", report.solver || "–"],
    ["RMS deviation", fmt(report.rms_deviation), "max deviation", fmt(report.max_deviation)],
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

const KIND = { mesh: "mesh", curve: "polyline", cloud: "cloud" };
const GEOGRAPHIC = new Set(["gpx", "geojson"]);

/**
 * Offer the formats that can hold `job`'s result (the registry's `kinds` and `geographic_only`
 * from /app/config.json; the server refuses the others with 422 all the same).
 */
function offerFormats(select, job, formats) {
  const kind = KIND[job.report?.kind];
  for (const option of select.options) {
    const f = (formats || []).find((x) => x.name === option.value);
    const holds = !f || !kind || !f.kinds || f.kinds.includes(kind) || f.name === job.format;
    const geo = !f?.geographic_only || GEOGRAPHIC.has(job.format);
    option.disabled = !(holds && geo);
    option.title = option.disabled ? `${f.title} cannot hold this ${job.report?.kind}` : "";
  }
}

/** Enable the download buttons for `job` (a succeeded Job). */
export function enableDownloads(job, formats = null) {
  const select = $("#download-format");
  offerFormats(select, job, formats);
  if (job.format && [...select.options].some((o) => o.value === job.format)) select.value = job.format;
  $("#download-result").disabled = false;
  $("#download-report").disabled = false;
  $("#download-result").onclick = async () => {
    const fmtName = select.value;
    clearErrors($("#results-section"));
    try { // the whole result, in any format that can hold it (422 names the ones that can)
      const response = await apiFetch(`${job.links.result}?format=${encodeURIComponent(fmtName)}`);
      saveBlob(await response.blob(), filenameFrom(response, `result.${fmtName}`));
    } catch (err) {
      showProblem(err.problem ? new ProblemError({ ...err.problem, field: "result" }) : err, "result");
    }
  };
  $("#download-report").onclick = async () => {
    const response = await apiFetch(job.links.report);
    const stem = (job.filename || job.id).replace(/\.[^.]*$/, "");
    saveBlob(await response.blob(), `${stem}.report.json`);
  };
}
