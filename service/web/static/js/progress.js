// Live progress of a job from GET /v1/jobs/{id}/events: stage, iteration, lambda, phi vs tau,
// elapsed time, a progress bar and the phi(lambda) plot.

import { readEvents } from "./sse.js";
import { apiJson } from "./api.js";
import { $, fmt, seconds } from "./ui.js";

const STAGE_LABELS = {
  queued: "queued", reading: "reading the input", neighborhoods: "neighbourhoods", laplacian: "Laplacian",
  analysis: "analysis (factorization)", search: "λ search", postprocess: "post-processing",
  writing: "writing the result", done: "done",
};
const STAGES = Object.keys(STAGE_LABELS);
const FINAL = new Set(["succeeded", "failed", "cancelled"]);

function percent(progress, tolerance) {
  if (Number.isFinite(progress.percent)) return progress.percent;
  const stage = STAGES.indexOf(progress.stage);
  if (progress.relative_error > 0 && (progress.stage === "search" || stage < 0)) {
    // each lambda iteration gains digits of |phi - tau| / tau until the tolerance
    const gained = Math.log10(1 / progress.relative_error) / Math.log10(1 / tolerance);
    return 40 + 55 * Math.min(1, Math.max(0, gained));
  }
  return stage >= 0 ? (100 * stage) / (STAGES.length - 1) : 0;
}

/** What the φ(λ) panel of a finished job with no λ tried says. */
function emptyHistory(r) {
  if (r.unchanged || r.noise_found === false) {
    return r.noise_found === false ? "no noise found: returned unchanged, no λ tried" : "nothing to smooth: returned unchanged";
  }
  return Number.isFinite(r.lambda) ? `λ = ${fmt(r.lambda, 4)} given: no search` : "this job tried no λ";
}

export class ProgressView {
  constructor(plot) {
    this.plot = plot;
    this.controller = null;
  }

  reset(text = "no job yet") {
    this.controller?.abort();
    this.plot.reset();
    $("#progress-bar").value = 0;
    $("#progress-text").textContent = text;
    for (const id of ["stage", "iteration", "lambda", "phi", "relerr", "elapsed"]) $(`#p-${id}`).textContent = "–";
  }

  showProgress(p, job) {
    const tolerance = job?.params?.tolerance || 1e-3;
    const stage = p.stage || (p.iteration ? "search" : null); // a record without a stage: the lambda search
    if (stage) $("#p-stage").textContent = STAGE_LABELS[stage] || stage;
    if (p.iteration !== undefined) $("#p-iteration").textContent = fmt(p.iteration);
    $("#p-lambda").textContent = fmt(p.lambda, 6);
    $("#p-phi").textContent = p.tau ? `${fmt(p.phi, 6)} vs τ = ${fmt(p.tau, 6)}` : fmt(p.phi, 6);
    $("#p-relerr").textContent = fmt(p.relative_error, 3);
    const elapsed = p.elapsed_seconds ?? (job?.started_at ? (Date.now() - Date.parse(job.started_at)) / 1000 : null);
    $("#p-elapsed").textContent = seconds(elapsed) + (Number.isFinite(p.eta_seconds) ? ` (about ${seconds(p.eta_seconds)} left)` : "");
    $("#progress-bar").value = percent(p, tolerance);
    if (p.tau) this.plot.setTau(p.tau);
    if (p.lambda > 0 && p.phi > 0 && p.iteration) this.plot.add(p.iteration, p.lambda, p.phi);
  }

  showStatus(job) {
    $("#progress-text").textContent = `job ${job.id.slice(0, 8)}: ${job.status}`;
    if (job.status === "running" && job.progress) this.showProgress(job.progress, job);
    if (job.status === "succeeded" && job.report) {
      const r = job.report;
      this.plot.finish(r.history || [], r.tau, emptyHistory(r));
      this.showProgress({ stage: "done", iteration: r.iterations, lambda: r.lambda, phi: r.phi, tau: r.tau,
        relative_error: r.relative_error, elapsed_seconds: job.run_seconds, percent: 100 }, job);
    }
  }

  /**
   * Follow job `id` until it is final; `onStatus(job)` gets every status event.
   * Falls back to polling the job if the event stream cannot be read.
   */
  async follow(id, onStatus) {
    this.controller?.abort();
    const controller = new AbortController();
    this.controller = controller;
    let last = null;
    const onEvent = (ev) => {
      if (controller.signal.aborted) return;
      const data = JSON.parse(ev.data);
      if (ev.type === "progress") this.showProgress(data, last);
      else if (ev.type === "status") { last = data; this.showStatus(data); onStatus(data); }
    };
    try {
      await readEvents(`/v1/jobs/${id}/events`, onEvent, controller.signal);
    } catch (err) {
      if (controller.signal.aborted) return;
      if ([401, 403, 404].includes(err.status)) { // polling would get the same answer
        $("#progress-text").textContent = `cannot follow job ${id.slice(0, 8)}: ${err.message}`;
        return;
      }
      $("#progress-text").textContent = `event stream lost (${err.message}); polling`;
    }
    while (!controller.signal.aborted && !(last && FINAL.has(last.status))) {
      await new Promise((resolve) => setTimeout(resolve, 1000));
      try {
        onEvent({ type: "status", data: JSON.stringify(await apiJson(`/v1/jobs/${id}`)) });
      } catch (err) {
        if ([401, 403, 404].includes(err.status)) break; // deleted meanwhile, or not ours
      }
    }
  }
}
