// The job list: status, links (status, result, report), cancel / delete, open.

import { apiFetch, apiJson, getApiKey } from "./api.js";
import { $, clearErrors, showProblem } from "./ui.js";

function link(href, text) {
  const a = document.createElement("a");
  a.href = href;
  a.textContent = text;
  a.target = "_blank";
  a.rel = "noopener";
  a.addEventListener("click", async (ev) => {
    if (!getApiKey()) return; // a plain link works without keys
    ev.preventDefault(); // with a key the request needs the Authorization header
    try {
      const response = await apiFetch(href);
      window.open(URL.createObjectURL(await response.blob()), "_blank", "noopener");
    } catch (err) { showProblem(err, "jobs"); }
  });
  return a;
}

function button(text, onClick) {
  const b = document.createElement("button");
  b.type = "button";
  b.className = "small secondary";
  b.textContent = text;
  b.addEventListener("click", onClick);
  return b;
}

export class JobList {
  /** @param {(job) => void} onOpen called with a job to show it */
  constructor(onOpen) {
    this.onOpen = onOpen;
    this.body = $("#jobs-table tbody");
    $("#jobs-refresh").addEventListener("click", () => this.refresh());
  }

  async refresh() {
    clearErrors($("#jobs-section"));
    let page;
    try {
      page = await apiJson("/v1/jobs?limit=25");
    } catch (err) {
      showProblem(err, "jobs");
      return;
    }
    this.body.replaceChildren(...page.items.map((job) => this.row(job)));
  }

  row(job) {
    const tr = document.createElement("tr");
    tr.dataset.jobId = job.id;
    const cells = [document.createElement("a"), job.filename || "–", job.status,
      job.created_at ? new Date(job.created_at).toLocaleString() : "–"];
    cells[0].href = "#";
    cells[0].textContent = job.id.slice(0, 8);
    cells[0].title = "show this job";
    cells[0].addEventListener("click", (ev) => { ev.preventDefault(); this.onOpen(job); });
    for (const c of cells) {
      const td = document.createElement("td");
      td.append(c);
      tr.append(td);
    }
    tr.children[2].className = `status-${job.status}`;
    const links = document.createElement("td");
    links.append(link(job.links.status, "status"));
    if (job.status === "succeeded") links.append(link(job.links.result, "result"), link(job.links.report, "report"));
    tr.append(links);
    const actions = document.createElement("td");
    const active = job.status === "queued" || job.status === "running";
    actions.append(button(active ? "cancel" : "delete", async () => {
      try {
        // cancel keeps the job readable (its final status shows); delete removes it (then 404)
        if (active) await apiFetch(`${job.links.status}/cancel`, { method: "POST" });
        else await apiFetch(job.links.status, { method: "DELETE" });
      } catch (err) { showProblem(err, "jobs"); }
      this.refresh();
    }));
    tr.append(actions);
    return tr;
  }
}
