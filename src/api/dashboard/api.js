// The API key and HTTP calls to rackd. The key lives in the browser's local storage; it is
// sent as `Authorization: Bearer` on HTTP calls and as `?token=` on the WebSocket (a browser
// cannot set headers there; rackd takes `?token=` nowhere else).

const STORAGE = 'rackd.key';

/** The key for this page's lifetime, in case local storage is disabled. */
let memory = '';

/** The stored key, or ''. */
export function getKey() {
  try {
    return localStorage.getItem(STORAGE) || '';
  } catch {
    return '';
  }
}

/** Stores a key; an empty one removes it. */
export function setKey(value) {
  const k = (value || '').trim();
  try {
    if (k) localStorage.setItem(STORAGE, k);
    else localStorage.removeItem(STORAGE);
  } catch {
    // Local storage can be disabled; the key then lasts as long as the page.
  }
  memory = k;
}

function key() {
  return getKey() || memory;
}

/**
 * Takes a key offered in the page's own address (`/?token=KEY`) out of the address bar at
 * once, so it stays in no bookmark or screenshot, and returns it (null when there is none,
 * or it is empty). Nothing is stored: the page asks the operator first, since a link
 * could otherwise switch this dashboard to someone else's key.
 */
export function takeTokenFromUrl() {
  const url = new URL(window.location.href);
  if (!url.searchParams.has('token')) return null;
  const token = (url.searchParams.get('token') || '').trim();
  url.searchParams.delete('token');
  window.history.replaceState(null, '', url.pathname + url.search + url.hash);
  return token || null;
}

/**
 * Who `candidate` belongs to, asked of rackd without using the key for anything else:
 * `{name, role}`, `{status}` when rackd refuses it, or null when rackd cannot be reached.
 */
export async function whoIs(candidate) {
  try {
    const response = await fetch('/api/v1/whoami', {
      headers: { Accept: 'application/json', Authorization: `Bearer ${candidate}` },
      cache: 'no-store',
    });
    if (!response.ok) return { status: response.status };
    return await response.json();
  } catch {
    return null;
  }
}

/** An error answer from the API: status, the API's code and message. */
export class ApiError extends Error {
  constructor(status, code, message) {
    super(message);
    this.status = status;
    this.code = code;
  }
}

const unauthorized = new Set();

/** Calls `listener(error)` whenever the API answers 401 (no key, or an unknown one). */
export function onUnauthorized(listener) {
  unauthorized.add(listener);
}

/** Calls the API; resolves to the JSON answer, rejects with an ApiError. */
export async function api(method, path, body) {
  const h = headers('application/json');
  // Every change says JSON, body or not: without keys rackd refuses one that does not (a
  // web page of another site cannot send that header without asking first).
  if (body !== undefined || (method !== 'GET' && method !== 'HEAD')) h['Content-Type'] = 'application/json';
  let response;
  try {
    response = await fetch(path, {
      method,
      headers: h,
      body: body === undefined ? undefined : JSON.stringify(body),
      cache: 'no-store',
    });
  } catch (e) {
    throw new ApiError(0, 'network', `rackd cannot be reached (${e.message})`);
  }
  let data = null;
  try {
    data = await response.json();
  } catch {
    data = null;
  }
  if (!response.ok) {
    const detail = data && data.error ? data.error : {};
    const error = new ApiError(response.status, detail.code || 'http', detail.message || response.statusText);
    if (response.status === 401) unauthorized.forEach((listener) => listener(error));
    throw error;
  }
  return data;
}

/** The headers of a call to rackd: the key, when there is one. */
function headers(accept) {
  const h = { Accept: accept };
  const k = key();
  if (k) h.Authorization = `Bearer ${k}`;
  return h;
}

/**
 * Reads a file the API makes (the alarm export) with the key, and hands it to the browser
 * as a download named `name`; a link cannot carry the key in a header.
 */
export async function download(path, name) {
  const response = await fetch(path, { headers: headers('*/*'), cache: 'no-store' });
  if (!response.ok) {
    let message = response.statusText;
    try {
      const data = await response.json();
      if (data && data.error) message = data.error.message;
    } catch {
      // Not JSON: the status says enough.
    }
    throw new ApiError(response.status, 'http', message);
  }
  const url = URL.createObjectURL(await response.blob());
  const link = document.createElement('a');
  link.href = url;
  link.download = name;
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
}

/** The status a `HEAD` of `path` answers (0 when rackd cannot be reached). */
export async function probe(path) {
  try {
    const response = await fetch(path, { method: 'HEAD', headers: headers('*/*'), cache: 'no-store' });
    return response.status;
  } catch {
    return 0;
  }
}

/** The WebSocket address of the live events, with the key and `since` when given. */
export function wsUrl(since) {
  const url = new URL('/api/v1/ws', window.location.href);
  url.protocol = url.protocol === 'https:' ? 'wss:' : 'ws:';
  const k = key();
  if (k) url.searchParams.set('token', k);
  if (since !== null && since !== undefined) url.searchParams.set('since', String(since));
  return url.toString();
}
