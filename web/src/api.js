// The REST client, live updates and small DOM helpers shared by every page.

/** An API error: the HTTP status and the body's `{error: {code, message, field}}`. */
export class ApiError extends Error {
  constructor(status, body) {
    const error = (body && body.error) || {};
    super(error.message || `HTTP ${status}`);
    this.status = status;
    this.code = error.code || null;
    this.field = error.field || null;
  }
}

/** The token the dashboard holds (the login page's, or the header's token field). */
export function storedToken() {
  return localStorage.getItem('crm-token') || '';
}

/**
 * Keeps the token for both ways the dashboard authenticates: the header on its own calls,
 * and the `crm_token` cookie, which the coordinator accepts for reads only, for what cannot
 * send a header (download links, the event stream).
 */
export function storeToken(token) {
  localStorage.setItem('crm-token', token);
  const secure = window.location.protocol === 'https:' ? '; Secure' : '';
  const value = token ? encodeURIComponent(token) : '';
  const expiry = token ? '' : '; Max-Age=0';
  document.cookie = `crm_token=${value}; Path=/; SameSite=Strict${secure}${expiry}`;
}

function authHeaders(headers) {
  const token = storedToken();
  if (token) headers.authorization = `Bearer ${token}`;
  return headers;
}

let loginShown = false;

/** The login page: the coordinator asked for a token this dashboard does not hold. */
export function showLogin(message) {
  if (loginShown) return;
  loginShown = true;
  // The login replaces the page's <main>, so the page's own code, still loading, draws into
  // the detached one and never over the form.
  const main = document.getElementById('main');
  const input = el('input', {
    id: 'login-token', type: 'password', autocomplete: 'current-password', required: true,
    placeholder: 'read token',
  });
  const form = el('form', {
    class: 'login',
    onsubmit: (e) => {
      e.preventDefault();
      storeToken(input.value.trim());
      window.location.reload();
    },
  },
  el('h1', {}, 'Sign in'),
  el('p', {}, message),
  el('label', {}, 'Token ', input),
  el('button', { type: 'submit' }, 'Sign in'));
  main.replaceWith(el('main', { id: 'main' }, form));
  document.title = 'Sign in · crm-grasp';
  input.focus();
}

async function parse(response) {
  const text = await response.text();
  let body = null;
  try {
    body = text ? JSON.parse(text) : null;
  } catch {
    body = { error: { message: text.slice(0, 200) } };
  }
  if (response.status === 401) {
    showLogin(storedToken()
      ? 'The coordinator did not accept this dashboard\'s token. Enter a token with the read scope.'
      : 'This coordinator needs a token. Enter a token with the read scope.');
  }
  if (!response.ok) throw new ApiError(response.status, body);
  return body;
}

export async function getJson(path) {
  return parse(await fetch(path, { headers: authHeaders({ accept: 'application/json' }) }));
}

export async function getText(path) {
  const response = await fetch(path, { headers: authHeaders({}) });
  if (!response.ok) await parse(response);
  return response.text();
}

/** POST (or another method) with the bearer token from the header's token field. */
export async function send(method, path, body) {
  const headers = authHeaders({ 'content-type': 'application/json' });
  return parse(await fetch(path, {
    method,
    headers,
    body: body === undefined ? undefined : JSON.stringify(body),
  }));
}

/** POST raw bytes (a file) with the bearer token; answers the JSON body. */
export async function sendBytes(method, path, bytes) {
  const headers = authHeaders({ 'content-type': 'application/octet-stream' });
  return parse(await fetch(path, { method, headers, body: bytes }));
}

/** Builds an element: `el('a', {href: '/'}, 'text', child)`. Text is never parsed as HTML. */
export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attrs)) {
    if (value === null || value === undefined || value === false) continue;
    if (key.startsWith('on')) node.addEventListener(key.slice(2), value);
    else if (key === 'class') node.className = value;
    else if (key === 'value') node.value = value;
    else node.setAttribute(key, value === true ? '' : value);
  }
  for (const child of children.flat(Infinity)) {
    if (child === null || child === undefined || child === false) continue;
    node.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  return node;
}

export function fmtTime(ms) {
  if (!ms) return '';
  const d = new Date(ms);
  const pad = (n) => String(n).padStart(2, '0');
  return `${d.getFullYear()}-${pad(d.getMonth() + 1)}-${pad(d.getDate())} ${pad(d.getHours())}:${pad(d.getMinutes())}:${pad(d.getSeconds())}`;
}

export function fmtDuration(ms) {
  if (ms === null || ms === undefined || ms < 0) return '';
  const s = Math.round(ms / 1000);
  if (s < 60) return `${s} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${s % 60} s`;
  return `${Math.floor(s / 3600)} h ${Math.floor((s % 3600) / 60)} min`;
}

export function fmtNum(value, digits = 2) {
  if (value === null || value === undefined || Number.isNaN(value)) return '';
  return Number(value).toFixed(digits);
}

/** How long a job ran (or has been running). */
export function duration(job) {
  if (!job.started_at) return '';
  return fmtDuration((job.finished_at || Date.now()) - job.started_at);
}

/** Stored JSON fields (spec, result, metric data) arrive as objects; null stays {}. */
export function asObject(value) {
  if (value && typeof value === 'object') return value;
  if (typeof value === 'string') {
    try { return JSON.parse(value); } catch { return {}; }
  }
  return {};
}

/** A job's phase before training (`{name, done, total}`), or null. */
export function phaseOf(job) {
  const phase = asObject(job.phase);
  return phase && phase.name ? phase : null;
}

export function phaseText(phase) {
  return `${phase.name}: ${phase.done.toLocaleString()} of ${phase.total.toLocaleString()}`;
}

/** The task ids a job's spec names, or "random". */
export function tasksOf(job) {
  const spec = asObject(job.spec);
  const tasks = [spec.task, ...(spec.tasks || [])].filter(Boolean);
  return tasks.length ? tasks.join(', ') : 'random tasks';
}

export function badge(state) {
  return el('span', { class: `badge ${state}` }, state);
}

/** A page's error: a box with the message. */
export function errorBox(err) {
  return el('div', { class: 'error', role: 'alert' }, err.message || String(err));
}

export function notFound(main, what) {
  main.replaceChildren(el('section', { class: 'not-found' },
    el('h1', {}, 'Not found'),
    el('p', {}, what),
    el('p', {}, el('a', { href: '/' }, 'Back to the jobs list'))));
  document.title = 'Not found · crm-grasp';
}

const listeners = new Set();
let source = null;
let timer = null;

/** Calls `callback` (debounced) whenever the coordinator reports a change. */
export function onChange(callback) {
  listeners.add(callback);
  if (!source) {
    const live = document.getElementById('live');
    source = new EventSource('/api/v1/events');
    source.addEventListener('open', () => { live.textContent = 'live'; live.className = 'live on'; });
    source.addEventListener('error', () => { live.textContent = 'reconnecting'; live.className = 'live off'; });
    source.addEventListener('changed', () => {
      clearTimeout(timer);
      timer = setTimeout(() => listeners.forEach((f) => f()), 250);
    });
    // Polling as a fallback when a proxy holds the event stream.
    setInterval(() => listeners.forEach((f) => f()), 15000);
  }
}

/** An SVG chart from `/api/v1/charts`, drawn inline so tests and users can inspect it. */
export async function drawChart(figure, query) {
  try {
    const svg = await getText(`/api/v1/charts?${new URLSearchParams(query)}`);
    figure.innerHTML = svg;
    figure.classList.remove('failed');
  } catch (err) {
    figure.replaceChildren(errorBox(err));
    figure.classList.add('failed');
  }
}

/** Smoothing and x-axis controls, remembered across pages. */
export function chartControls(onInput) {
  const smooth = localStorage.getItem('crm-smooth') || '0.6';
  const axis = localStorage.getItem('crm-x') || 'steps';
  const value = el('output', {}, smooth);
  const range = el('input', {
    type: 'range', min: '0', max: '0.99', step: '0.01', value: smooth, name: 'smooth',
    oninput: (e) => { value.textContent = e.target.value; },
    onchange: (e) => { localStorage.setItem('crm-smooth', e.target.value); onInput(); },
  });
  const select = el('select', {
    name: 'x', onchange: (e) => { localStorage.setItem('crm-x', e.target.value); onInput(); },
  }, ['steps', 'episodes', 'wall'].map((x) => el('option', { value: x, selected: x === axis },
    x === 'wall' ? 'wall time' : x)));
  return el('div', { class: 'controls' },
    el('label', {}, 'smoothing ', range, ' ', value),
    el('label', {}, 'x axis ', select));
}

export function chartSettings() {
  return {
    smooth: localStorage.getItem('crm-smooth') || '0.6',
    x: localStorage.getItem('crm-x') || 'steps',
  };
}

/** Bytes as KiB, MiB or GiB. */
export function fmtBytes(bytes) {
  const units = ['bytes', 'KiB', 'MiB', 'GiB'];
  let value = bytes;
  let unit = 0;
  while (value >= 1024 && unit < units.length - 1) {
    value /= 1024;
    unit += 1;
  }
  return unit === 0 ? `${value} bytes` : `${value.toFixed(1)} ${units[unit]}`;
}
