// The API key and HTTP calls to rackd. The key lives in the browser's local storage; it is
// sent as `Authorization: Bearer` on HTTP calls and as `?token=` on the WebSocket (a browser
// cannot set headers there).

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
export function setKey(key) {
  const k = (key || '').trim();
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
 * Takes a key given in the page's own address (`/?token=KEY`), stores it and removes it
 * from the address bar, so it does not end up in bookmarks or screenshots.
 */
export function adoptTokenFromUrl() {
  const url = new URL(window.location.href);
  const token = url.searchParams.get('token');
  if (token === null) return false;
  setKey(token);
  url.searchParams.delete('token');
  window.history.replaceState(null, '', url.pathname + url.search + url.hash);
  return true;
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
  const headers = { Accept: 'application/json' };
  const k = key();
  if (k) headers.Authorization = `Bearer ${k}`;
  if (body !== undefined) headers['Content-Type'] = 'application/json';
  let response;
  try {
    response = await fetch(path, {
      method,
      headers,
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

/** The WebSocket address of the live events, with the key and `since` when given. */
export function wsUrl(since) {
  const url = new URL('/api/v1/ws', window.location.href);
  url.protocol = url.protocol === 'https:' ? 'wss:' : 'ws:';
  const k = key();
  if (k) url.searchParams.set('token', k);
  if (since !== null && since !== undefined) url.searchParams.set('since', String(since));
  return url.toString();
}
