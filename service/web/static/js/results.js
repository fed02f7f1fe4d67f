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
    ["RMS displacement", fmt(report.rms_displacement), "max displacement", fmt(report.max_displacement)],
    ["points", fmt(report.n_points), "kind / dimension", `${report.kind} / ${report.dimension}-D`],
    ["Laplacian", report.laplacian || "–", "weights", report.weights || "–"],
    ["fixed points", fmt(report.n_fixed), "volume scale", fmt(report.volume_scale)],
    ["noise estimate σ̂", noiseText(report), "τ chosen by", report.tau_rule || "–"],
  ];
  if (report.tau_how) rows.push(["how τ was chosen", report.tau_how]);
  const keys = Object.keys(t).filter((k) => k !== "total");
  for (let i = 0; i < keys.length; i += 2) {
    const row = [`time: ${keys[i]}`, seconds(t[keys[i]])];
    if (keys[i + 1]) row.push(`time: ${keys[i + 1]}`, seconds(t[keys[i + 1]]));
    rows.push(row);
  }
  if (t.total !== undefined) rows.push(["time: total (smoothing)", seconds(t.total)]);
  fillTable($("#report-table"), rows);
  showNotices(report);
  const gamma = report.spectrum?.gamma;
  $("#spectrum-figure").hidden = !gamma;
  if (gamma) drawSpectrum($("#spectrum-plot"), gamma);
}

function noiseText(report) {
  if (report.noise_found === false) return "no noise found (σ̂ = 0): input returned unchanged";
  return report.sigma_estimate == null ? "–" : fmt(report.sigma_estimate, 4);
}

/** The warnings above the report table, shape warnings first and marked (issue 20). */
function showNotices(report) {
  const table = $("#report-table");
  let box = document.getElementById("report-notices");
  if (!box) {
    box = document.createElement("div");
    box.id = "report-notices";
    box.setAttribute("role", "status");
    table.parentNode.insertBefore(box, table);
  }
  const shape = new Set(report.shape_warnings || []);
  const items = [...shape, ...(report.warnings || []).filter((w) => !shape.has(w))];
  box.replaceChildren(...items.map((w) => {
    const p = document.createElement("p");
    p.className = shape.has(w) ? "notice notice-shape" : "notice";
    p.textContent = (shape.has(w) ? "⚠ shape: " : "note: ") + w;
    if (shape.has(w)) p.style.color = "#b00020";
    return p;
  }));
  box.hidden = items.length === 0;
}

export function clearReport() {
  $("#report-table").replaceChildren();
  document.getElementById("report-notices")?.replaceChildren();
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
    const holds = !f || !kind || !f.kinds || f.kinds.includes(kind) || f.name === (job.input_format ?? job.format);
    const geo = !f?.geographic_only || GEOGRAPHIC.has(job.input_format ?? job.format);
    option.disabled = !(holds && geo);
    option.title = option.disabled ? `${f.title} cannot hold this ${job.report?.kind}` : "";
  }
}

/** Enable the download buttons for `job` (a succeeded Job). */
export function enableDownloads(job, formats = null) {
  const select = $("#download-format");
  const input = job.input_format ?? job.format;
  offerFormats(select, job, formats);
  if (input && [...select.options].some((o) => o.value === input)) select.value = input;
  $("#download-result").disabled = false;
  $("#download-report").disabled = false;
  $("#download-result").onclick = async () => {
    const fmtName = select.value;
    clearErrors($("#results-section"));
    try { // the whole result, in any format that can hold it (422 names the ones that can)
      const response = await apiFetch(`${job.links.result}?output_format=${encodeURIComponent(fmtName)}`);
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
