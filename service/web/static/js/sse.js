// Server-sent events read with fetch() and a stream reader, so that the Authorization header
// can be sent (EventSource cannot). Parsing follows the WHATWG event-stream rules: lines end
// with \n, \r\n or \r; "field: value"; a blank line dispatches; lines starting with ":" are
// comments (the server's pings).

import { apiFetch } from "./api.js";

export function parseEventStream(onEvent) {
  let buffer = "";
  let event = { type: "message", data: [], id: null };
  const dispatch = () => {
    if (event.data.length) onEvent({ type: event.type, data: event.data.join("\n"), id: event.id });
    event = { type: "message", data: [], id: event.id };
  };
  const line = (text) => {
    if (text === "") { dispatch(); return; }
    if (text.startsWith(":")) return;
    const colon = text.indexOf(":");
    const field = colon < 0 ? text : text.slice(0, colon);
    let value = colon < 0 ? "" : text.slice(colon + 1);
    if (value.startsWith(" ")) value = value.slice(1);
    if (field === "event") event.type = value;
    else if (field === "data") event.data.push(value);
    else if (field === "id") event.id = value;
  };
  return (chunk) => {
    buffer += chunk;
    const parts = buffer.split(/\r\n|\r(?!$)|\n/);
    buffer = parts.pop();
    parts.forEach(line);
  };
}

/**
 * Read the events of `url` until the server ends the stream or `signal` aborts.
 * `onEvent({type, data, id})` gets every event; resolves when the stream ends.
 */
export async function readEvents(url, onEvent, signal) {
  const response = await apiFetch(url, { signal, headers: { Accept: "text/event-stream" } });
  const reader = response.body.getReader();
  const decoder = new TextDecoder();
  const feed = parseEventStream(onEvent);
  try {
    for (;;) {
      const { value, done } = await reader.read();
      if (done) break;
      feed(decoder.decode(value, { stream: true }));
    }
    feed(decoder.decode() + "\n\n");
  } finally {
    reader.releaseLock();
  }
}
