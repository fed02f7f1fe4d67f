// The geosmooth page: pick an input, see what was read, set the parameters (a form generated
// from the SmoothingParams schema of /openapi.json), submit a job, watch it converge, compare
// before and after in 3-D, download the results.

import { apiFetch, apiJson, getApiKey, ProblemError, setApiKey } from "./api.js";
import { SchemaForm } from "./schemaform.js";
import { PhiPlot } from "./plot.js";
import { ProgressView } from "./progress.js";
import { JobList } from "./jobs.js";
import { clearReport, enableDownloads, showReport } from "./results.js";
import { loadResultView, showInputView } from "./compare.js";
import { $, bboxText, clearErrors, fillTable, fmt, showProblem } from "./ui.js";

const state = { config: null, form: null, input: null, job: null };
const FINAL = new Set(["succeeded", "failed", "cancelled"]);

function paramsSchema(spec) {
  const resolve = (s) => (s && s.$ref ? s.$ref.slice(2).split("/").reduce((n, k) => n?.[k], spec) : s);
  const body = spec.paths?.["/v1/jobs"]?.post?.requestBody?.content?.["application/json"]?.schema;
  return resolve(resolve(body)?.properties?.params) || spec.components.schemas.SmoothingParams;
}

async function init() {
  const [config, spec] = await Promise.all([apiJson("/app/config.json"), apiJson("/openapi.json")]);
  state.config = config;
  state.limits = await apiJson("/v1/limits").catch(() => config); // the key's bounds (401: the defaults)
  const schema = paramsSchema(spec);
  state.form = new SchemaForm($("#params-fields"), schema, spec);
  $("#params-intro").textContent = (schema.description || "").split("\n\n")[0];
  const names = config.formats.map((f) => f.name);
  for (const f of config.formats) {
    $("#format-select").append(new Option(`${f.title} (.${f.extensions.join(", .")})`, f.name));
    if (f.writable) $("#download-format").append(new Option(f.title, f.name));
  }
  $("#file-input").accept = config.formats.flatMap((f) => f.extensions.map((e) => `.${e}`)).join(",");
  $("#format-hint").textContent = `Formats: ${config.formats.map((f) => f.title).join(", ")}. ${limitsText(state.limits)}`;
  for (const s of config.samples) $("#sample-select").append(new Option(s.name, s.url));
  state.formats = names;
  wireInput();
  wireViewerControls();
  $("#params-form").addEventListener("submit", (ev) => { ev.preventDefault(); submit(); });
  $("#api-key").value = getApiKey();
  $("#api-key").addEventListener("change", (ev) => { setApiKey(ev.target.value.trim()); state.jobs.refresh(); });
  state.plot = new PhiPlot($("#phi-plot"));
  state.progress = new ProgressView(state.plot);
  state.jobs = new JobList((job) => openJob(job));
  state.jobs.refresh();
  document.body.dataset.ready = "true";
}

/** The bounds the server applies to this page's key, as one sentence (from GET /v1/limits). */
function limitsText(limits) {
  const mib = (b) => (b >= 2 ** 20 ? `${fmt(Math.round(b / 2 ** 20))} MiB` : `${fmt(b)} bytes`);
  const faces = limits.max_faces ? ` and ${fmt(limits.max_faces)} faces` : "";
  return `This server takes inputs of up to ${fmt(limits.max_points)} points${faces}, in files of up to ${mib(limits.max_upload_bytes)}.`;
}

function wireInput() {
  const zone = $("#drop-zone");
  zone.addEventListener("dragover", (ev) => { ev.preventDefault(); zone.classList.add("dragover"); });
  zone.addEventListener("dragleave", () => zone.classList.remove("dragover"));
  zone.addEventListener("drop", (ev) => {
    ev.preventDefault();
    zone.classList.remove("dragover");
    const file = ev.dataTransfer?.files?.[0];
    if (file) loadInput(file, file.name);
  });
  $("#file-input").addEventListener("change", (ev) => {
    const file = ev.target.files[0];
    if (file) loadInput(file, file.name);
  });
  $("#sample-select").addEventListener("change", async (ev) => {
    const url = ev.target.value;
    if (!url) return;
    try {
      const response = await apiFetch(url);
      loadInput(await response.blob(), url.split("/").pop());
    } catch (err) { showProblem(err, "file"); }
  });
  const reread = () => state.input && loadInput(state.input.file, state.input.name);
  $("#format-select").addEventListener("change", reread);
  $("#weld").addEventListener("change", reread);
}

function inputForm(file, name) {
  const body = new FormData();
  body.append("file", file, name);
  if ($("#format-select").value) body.append("input_format", $("#format-select").value);
  if ($("#weld").checked) body.append("weld", "true");
  return body;
}

async function loadInput(file, name) {
  clearErrors($("#input-section"));
  state.input = null;
  $("#submit").disabled = true;
  $("#info").hidden = true;
  $("#info-file").textContent = `${name}: reading…`;
  const maxBytes = state.limits?.max_upload_bytes;
  if (maxBytes && file.size > maxBytes) {
    showProblem(new ProblemError({ status: 413, title: "Request Entity Too Large", field: "file",
      detail: `${name} has ${fmt(file.size)} bytes; this server takes files of up to ${fmt(maxBytes)} bytes` }), "file");
    return;
  }
  let info;
  try {
    info = await apiJson("/v1/info?preview=true", { method: "POST", body: inputForm(file, name) });
  } catch (err) {
    showProblem(err, "file");
    return;
  }
  state.input = { file, name, info, ...showInputView(info) };
  showInfo(info, name);
  $("#submit").disabled = false;
}

function useButton(name, value) {
  const b = document.createElement("button");
  b.type = "button";
  b.textContent = "use";
  b.addEventListener("click", () => {
    for (const other of ["tau", "rms", "lam"]) if (state.form.has(other)) state.form.set(other, null);
    state.form.set(name, value);
    state.form.focus(name);
  });
  const span = document.createElement("span");
  span.append(fmt(value), b);
  return span;
}

function showInfo(info, name) {
  const box = info.bbox || { min: [], max: [] };
  const bbox = bboxText(box);
  const rows = [
    ["kind", info.kind, "points", fmt(info.n_points)],
    ["dimension", `${info.dimension}-D`, info.kind === "mesh" ? "faces" : "polylines", fmt(info.kind === "mesh" ? info.n_faces : info.n_polylines)],
    ["neighbour pairs", fmt(info.n_edges), "mean spacing", fmt(info.mean_spacing)],
    ["bounding box", bbox, "format", info.input_format ?? info.format],
    info.phi0_exact === false
      ? ["φ(0) ≤", `${fmt(info.phi0)} (closed-form bound; the job computes φ(0))`, "valid τ", `(0, ≤ ${fmt(info.tau_range[1])})`]
      : ["φ(0)", fmt(info.phi0), "valid τ", `(0, ${fmt(info.tau_range[1])})`],
    ["noise estimate σ", fmt(info.sigma_estimate), "valid rms", `(0, ${fmt(info.rms_range[1])})`],
  ];
  if (info.noise) rows.push(["noise", info.noise]);
  const suggest = [];
  if (info.suggested_tau) suggest.push("suggested τ", useButton("tau", info.suggested_tau));
  if (info.suggested_rms) suggest.push("suggested rms", useButton("rms", info.suggested_rms));
  if (suggest.length) rows.push(suggest);
  fillTable($("#info-table"), rows);
  $("#info-file").textContent = name;
  $("#info-notes").replaceChildren(...(info.notes || []).map((n) => Object.assign(document.createElement("li"), { textContent: n })));
  const lt = info.phi0_exact === false ? "< at most" : "<"; // a bound: the job checks the exact range
  state.form.setHint("tau", `valid: 0 < τ ${lt} ${fmt(info.tau_range[1])}`);
  state.form.setHint("rms", `valid: 0 < rms ${lt} ${fmt(info.rms_range[1])}`);
  $("#info").hidden = false;
}

async function submit() {
  clearErrors($("#params-section"));
  clearErrors($("#input-section"));
  if (!state.input) return;
  const body = inputForm(state.input.file, state.input.name);
  body.append("params", JSON.stringify(state.form.values()));
  $("#submit-status").textContent = "submitting…";
  let job;
  try {
    job = await apiJson("/v1/jobs", { method: "POST", body });
  } catch (err) {
    $("#submit-status").textContent = "";
    showProblem(err, "params");
    return;
  }
  $("#submit-status").textContent = `job ${job.id.slice(0, 8)} submitted`;
  follow(job, state.input);
}

function openJob(job) {
  const sameInput = state.job?.id === job.id ? state.job.input : null;
  follow(job, sameInput);
}

function follow(job, input) {
  state.job = { id: job.id, input, done: false };
  document.body.dataset.jobId = job.id;
  clearReport();
  $("#pane-after").dataset.resultLoaded = "false";
  state.progress.reset(`job ${job.id.slice(0, 8)}: ${job.status}`);
  state.jobs.refresh();
  state.progress.follow(job.id, (record) => onStatus(record));
}

async function onStatus(job) {
  const current = state.job;
  if (!current || current.id !== job.id || current.done || !FINAL.has(job.status)) return;
  current.done = true;
  state.jobs.refresh();
  if (job.status === "succeeded") {
    showReport(job.report);
    enableDownloads(job, state.config.formats);
    try {
      await loadResultView(job, current.input);
    } catch (err) { showProblem(err, "result"); }
  } else if (job.status === "failed" && job.error) {
    showProblem(new ProblemError(job.error), "params");
  }
}

function wireViewerControls() {
  const viewer = () => state.input?.viewer;
  $("#v-shading").addEventListener("change", (ev) => viewer()?.setOption("shading", ev.target.value));
  $("#v-wireframe").addEventListener("change", (ev) => viewer()?.setOption("wireframe", ev.target.checked));
  $("#v-deviation").addEventListener("change", (ev) => viewer()?.setOption("deviation", ev.target.checked));
  $("#v-pointsize").addEventListener("input", (ev) => viewer()?.setOption("pointSize", Number(ev.target.value)));
  $("#v-reset").addEventListener("click", () => viewer()?.reset());
}

init().catch((err) => {
  document.body.dataset.ready = "error";
  showProblem(err, "body");
});
