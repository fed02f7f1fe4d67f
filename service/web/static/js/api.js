// HTTP helpers: the API key (kept in localStorage, sent as Authorization: Bearer) and
// RFC 9457 problem details turned into exceptions that name the field at fault.

const KEY_STORAGE = "geosmooth.apiKey";

export function getApiKey() {
  try { return localStorage.getItem(KEY_STORAGE) || ""; } catch { return ""; }
}

export function setApiKey(value) {
  try {
    if (value) localStorage.setItem(KEY_STORAGE, value); else localStorage.removeItem(KEY_STORAGE);
  } catch { /* private mode: the key lives for this page only */ }
}

export function authHeaders(extra = {}) {
  const key = getApiKey();
  return key ? { ...extra, Authorization: `Bearer ${key}` } : { ...extra };
}

/** An error answered by the API (problem+json), or a network failure (status 0). */
export class ProblemError extends Error {
  constructor(problem) {
    super(problem.detail || problem.title || "request failed");
    this.problem = problem;
    this.status = problem.status || 0;
    this.field = problem.field || null;
  }

  /** [{field, message}] for every input at fault (at least one entry). */
  fieldErrors() {
    const p = this.problem;
    if (Array.isArray(p.errors) && p.errors.length) {
      return p.errors.map((e) => ({ field: e.field || p.field || "", message: e.message || p.detail }));
    }
    return [{ field: p.field || "", message: this.message }];
  }
}

export async function problemFrom(response) {
  let body = null;
  try { body = await response.json(); } catch { /* not JSON */ }
  if (!body || typeof body !== "object") {
    body = { status: response.status, title: response.statusText, detail: `HTTP ${response.status} ${response.statusText}` };
  }
  body.status = body.status || response.status;
  return new ProblemError(body);
}

/** fetch() with the API key; throws ProblemError for non-2xx answers and network failures. */
export async function apiFetch(url, options = {}) {
  const init = { ...options, headers: authHeaders(options.headers || {}) };
  let response;
  try {
    response = await fetch(url, init);
  } catch (err) {
    if (err.name === "AbortError") throw err;
    throw new ProblemError({ status: 0, title: "Network error", detail: `cannot reach the server: ${err.message}` });
  }
  if (!response.ok) throw await problemFrom(response);
  return response;
}

export async function apiJson(url, options = {}) {
  const response = await apiFetch(url, options);
  return response.status === 204 ? null : response.json();
}
