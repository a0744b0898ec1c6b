// The dashboard's entry: picks the page from the path, keeps the token field and the
// workers count in the header.
import { getJson, notFound, onChange, storeToken, storedToken } from './api.js';
import { renderJobs } from './jobs.js';
import { renderRun } from './run.js';
import { renderCompare } from './compare.js';
import { renderTopology } from './topology.js';
import { renderModels } from './models.js';
import { renderSweep, renderSweeps } from './sweeps.js';

const main = document.getElementById('main');
const path = window.location.pathname.replace(/\/+$/, '') || '/';

const token = document.getElementById('token');
token.value = storedToken();
// The cookie follows the stored token (a dashboard signed in before cookies existed).
if (token.value && !document.cookie.includes('crm_token=')) storeToken(token.value);
token.addEventListener('change', () => storeToken(token.value.trim()));

async function workers() {
  try {
    const body = await getJson('/api/v1/workers');
    const alive = body.workers.filter((w) => w.alive).length;
    document.getElementById('workers').textContent =
      `${alive} worker${alive === 1 ? '' : 's'} alive`;
  } catch { /* the header stays quiet */ }
}
workers();
onChange(workers);

const nav = (name) => document.querySelector(`[data-nav="${name}"]`)?.classList.add('active');
const run = path.match(/^\/runs\/([^/]+)$/);
const sweep = path.match(/^\/sweeps\/([^/]+)$/);
if (path === '/') {
  nav('jobs');
  renderJobs(main);
} else if (run) {
  nav('jobs');
  renderRun(main, run[1]);
} else if (path === '/compare') {
  nav('compare');
  renderCompare(main);
} else if (path === '/sweeps') {
  nav('sweeps');
  renderSweeps(main);
} else if (sweep) {
  nav('sweeps');
  renderSweep(main, sweep[1]);
} else if (path === '/models') {
  nav('models');
  renderModels(main);
} else if (path === '/topology') {
  nav('topology');
  renderTopology(main);
} else {
  notFound(main, `There is no page at ${path}.`);
}
