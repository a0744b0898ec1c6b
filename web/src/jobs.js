// The jobs page: a live list with filters, cancel and re-run, selection for comparison, and
// the form that submits training and evaluation jobs.
import {
  asObject, badge, duration, el, errorBox, fmtNum, fmtTime, getJson, onChange, send, tasksOf, phaseOf, phaseText,
} from './api.js';

const STATES = ['queued', 'running', 'succeeded', 'failed', 'cancelled'];
const ALGORITHMS = ['crm-ppo', 'ippo', 'lppo', 'crm-sac', 'ppo'];

export async function renderJobs(main) {
  const params = new URLSearchParams(window.location.search);
  const filters = { state: params.get('state') || '', algorithm: params.get('algorithm') || '', kind: params.get('kind') || '' };
  const selected = new Set();
  const tbody = el('tbody');
  const message = el('div', { class: 'message', role: 'status' });
  const compareButton = el('button', {
    type: 'button', disabled: true, id: 'compare-selected',
    onclick: () => { window.location.href = `/compare?runs=${[...selected].join(',')}`; },
  }, 'Compare selected');

  const filter = (name, values) => el('label', {}, `${name} `, el('select', {
    name: `filter-${name}`,
    onchange: (e) => {
      filters[name] = e.target.value;
      const query = new URLSearchParams(Object.entries(filters).filter(([, v]) => v));
      window.history.replaceState(null, '', `/${query.toString() ? `?${query}` : ''}`);
      refresh();
    },
  }, el('option', { value: '' }, 'all'), values.map((v) => el('option', { value: v, selected: v === filters[name] }, v))));

  let catalog = { tasks: [], topologies: [] };
  let worlds = [{ name: 'crm', builtin: true }];
  try {
    catalog = await getJson('/api/v1/tasks');
    worlds = (await getJson('/api/v1/worlds')).worlds;
  } catch (err) { message.replaceChildren(errorBox(err)); }

  main.replaceChildren(
    el('h1', {}, 'Jobs'),
    el('div', { class: 'toolbar' },
      filter('state', STATES), filter('algorithm', ALGORITHMS), filter('kind', ['train', 'eval']),
      el('span', { class: 'spacer' }), compareButton),
    message,
    el('table', { class: 'jobs', id: 'jobs' },
      el('thead', {}, el('tr', {},
        ['', 'id', 'kind', 'state', 'algorithm', 'tasks', 'progress', 'steps/s', 'worker', 'started', 'duration', 'result', ''].map((h) => el('th', {}, h)))),
      tbody),
    submitForm(catalog, worlds, (job) => {
      message.replaceChildren(el('div', { class: 'ok' }, `Job ${job.id} queued.`));
      refresh();
    }));

  async function act(job, action) {
    try {
      await send('POST', `/api/v1/jobs/${job.id}/${action}`);
      message.replaceChildren(el('div', { class: 'ok' }, `Job ${job.id}: ${action === 'cancel' ? 'cancelled' : 're-run queued'}.`));
    } catch (err) {
      message.replaceChildren(errorBox(err));
    }
    refresh();
  }

  let workerNames = {};
  let checkpointRuns = {};
  async function refresh() {
    const query = new URLSearchParams(Object.entries(filters).filter(([, v]) => v));
    query.set('limit', '200');
    let jobs;
    try {
      const [body, workers, checkpoints] = await Promise.all([
        getJson(`/api/v1/jobs?${query}`), getJson('/api/v1/workers'), getJson('/api/v1/checkpoints')]);
      jobs = body.jobs;
      workerNames = Object.fromEntries(workers.workers.map((w) => [w.id, w.name]));
      checkpointRuns = Object.fromEntries(checkpoints.checkpoints.map((c) => [c.id, c.job_id]));
    } catch (err) {
      message.replaceChildren(errorBox(err));
      return;
    }
    tbody.replaceChildren(...jobs.map(row));
    if (!jobs.length) tbody.append(el('tr', {}, el('td', { colspan: 13, class: 'muted' }, 'No jobs match. Submit one below.')));
  }

  function row(job) {
    const isTrain = job.kind === 'train';
    const check = isTrain ? el('input', {
      type: 'checkbox', 'aria-label': `select run ${job.id}`, checked: selected.has(job.id),
      onchange: (e) => {
        if (e.target.checked) selected.add(job.id); else selected.delete(job.id);
        compareButton.disabled = selected.size < 1;
        compareButton.textContent = `Compare selected (${selected.size})`;
      },
    }) : '';
    const link = isTrain
      ? el('a', { href: `/runs/${job.id}` }, `#${job.id}`)
      : job.checkpoint_id && checkpointRuns[job.checkpoint_id]
        ? el('a', { href: `/runs/${checkpointRuns[job.checkpoint_id]}`, title: `evaluates checkpoint ${job.checkpoint_id}` }, `#${job.id}`)
        : `#${job.id}`;
    // Before training reports, a long phase (demonstrations, behaviour cloning) shows its own
    // progress in the bar.
    const phase = job.state === 'running' ? phaseOf(job) : null;
    const pct = Math.round(100 * (phase ? phase.done / Math.max(phase.total, 1) : (job.progress || 0)));
    let result = job.error ? el('span', { class: 'bad', title: job.error }, 'error') : '';
    if (job.result && !isTrain && asObject(job.result).success_rate !== undefined) {
      result = `success ${fmtNum(asObject(job.result).success_rate)}`;
    }
    const actions = [];
    if (job.state === 'queued' || job.state === 'running') {
      actions.push(el('button', { type: 'button', class: 'small', onclick: () => act(job, 'cancel') }, 'Cancel'));
    } else {
      actions.push(el('button', { type: 'button', class: 'small', onclick: () => act(job, 'rerun') }, 'Re-run'));
    }
    return el('tr', { 'data-job': job.id, 'data-state': job.state },
      el('td', {}, check), el('td', {}, link), el('td', {}, job.kind), el('td', {}, badge(job.state)),
      el('td', {}, job.algorithm), el('td', { class: 'tasks' }, tasksOf(job)),
      el('td', {}, el('div', { class: phase ? 'progress phase' : 'progress', title: phase ? phaseText(phase) : `${job.steps} steps` },
        el('div', { class: 'bar', style: `width:${pct}%` }), el('span', {}, phase ? `${phase.name} ${pct}%` : `${pct}%`))),
      el('td', {}, job.steps_per_s ? Math.round(job.steps_per_s) : ''),
      el('td', {}, workerNames[job.worker_id] || job.worker_id || ''),
      el('td', {}, fmtTime(job.started_at)), el('td', {}, duration(job)),
      el('td', {}, result), el('td', {}, actions));
  }

  refresh();
  onChange(refresh);
}

/** The submit form; API errors appear next to the field they name. */
function submitForm(catalog, worlds, onQueued) {
  const field = (name, label, input, help) => el('div', { class: 'field', 'data-field': name },
    el('label', { for: `f-${name}` }, label), input, help ? el('small', { class: 'muted' }, help) : null,
    el('div', { class: 'field-error', 'data-error-for': name }));
  const kind = el('select', { id: 'f-kind', name: 'kind' }, el('option', { value: 'train' }, 'train'), el('option', { value: 'eval' }, 'eval'));
  const taskOptions = (list) => list.map((t) => el('option', { value: t.id }, `${t.id} (${t.topology})`));
  const inputs = {
    world: el('select', { id: 'f-world', name: 'world' },
      worlds.map((w) => el('option', { value: w.name }, w.builtin ? `${w.name} (built in)` : `${w.name} (${w.tasks} tasks)`))),
    algorithm: el('select', { id: 'f-algorithm', name: 'algorithm' }, ALGORITHMS.map((a) => el('option', { value: a }, a))),
    tasks: el('select', { id: 'f-tasks', name: 'tasks', multiple: true, size: 6 }, taskOptions(catalog.tasks)),
    steps: el('input', { id: 'f-steps', name: 'steps', type: 'text', inputmode: 'numeric', value: '20000' }),
    seed: el('input', { id: 'f-seed', name: 'seed', type: 'text', inputmode: 'numeric', value: '0' }),
    topology: el('select', { id: 'f-topology', name: 'topology' },
      ['task', 'auto', ...catalog.topologies].map((t) => el('option', { value: t }, t))),
    envs: el('input', { id: 'f-envs', name: 'envs', type: 'text', inputmode: 'numeric', placeholder: 'one per worker core' }),
    config: el('textarea', { id: 'f-config', name: 'config', rows: 3, placeholder: '{"learning_rate": 0.0003}' }),
    imitation: el('input', { id: 'f-imitation', name: 'imitation', type: 'text', inputmode: 'numeric', placeholder: 'off' }),
    curriculum: el('input', { id: 'f-curriculum', name: 'curriculum', type: 'checkbox' }),
    objective: el('select', { id: 'f-objective', name: 'objective' },
      el('option', { value: 'scripted' }, 'scripted (the paper: the arm executes it)'),
      el('option', { value: 'learned' }, 'learned (the policy executes it)')),
    checkpoint_id: el('input', { id: 'f-checkpoint_id', name: 'checkpoint_id', type: 'text', inputmode: 'numeric' }),
    episodes: el('input', { id: 'f-episodes', name: 'episodes', type: 'text', inputmode: 'numeric', value: '1000' }),
    record_every: el('input', { id: 'f-record_every', name: 'record_every', type: 'text', inputmode: 'numeric', placeholder: 'off' }),
    record_connect: el('input', { id: 'f-record_connect', name: 'record_connect', type: 'text', placeholder: 'rerun+http://127.0.0.1:9876/proxy' }),
    hold_s: el('input', { id: 'f-hold_s', name: 'hold_s', type: 'text', inputmode: 'decimal', placeholder: '5 (the paper)' }),
  };
  const formError = el('div', { class: 'field-error', 'data-error-for': '' });
  const trainOnly = [
    field('algorithm', 'algorithm', inputs.algorithm),
    field('steps', 'steps', inputs.steps, 'environment steps'),
    field('envs', 'environments', inputs.envs),
    field('config', 'config (JSON)', inputs.config, 'PPO settings, or SAC settings under "sac" for crm-sac'),
    field('imitation', 'clone the oracle first (episodes)', inputs.imitation, 'behaviour cloning before PPO (crm-ppo, ippo, lppo)'),
    field('curriculum', 'task curriculum', inputs.curriculum, 'draw tasks more often where the policy fails (the paper: uniform)'),
  ];
  const evalOnly = [
    field('checkpoint_id', 'checkpoint id', inputs.checkpoint_id),
    field('episodes', 'episodes', inputs.episodes, 'the paper evaluates 1,000'),
  ];
  const show = () => {
    trainOnly.forEach((f) => { f.hidden = kind.value !== 'train'; });
    evalOnly.forEach((f) => { f.hidden = kind.value !== 'eval'; });
  };
  kind.addEventListener('change', show);
  // Another world has other tasks.
  inputs.world.addEventListener('change', async () => {
    try {
      const other = await getJson(`/api/v1/tasks?world=${encodeURIComponent(inputs.world.value)}`);
      inputs.tasks.replaceChildren(...taskOptions(other.tasks));
    } catch (err) { showError(form, formError, err); }
  });

  const form = el('form', { id: 'submit-job', class: 'card', novalidate: true },
    el('h2', {}, 'Submit a job'),
    el('div', { class: 'grid' },
      field('kind', 'kind', kind), field('world', 'world', inputs.world, 'the hand, objects and tasks (GET /api/v1/worlds)'),
      ...trainOnly, ...evalOnly,
      field('tasks', 'tasks', inputs.tasks, 'none selected: random tasks'),
      field('seed', 'seed', inputs.seed), field('topology', 'topology', inputs.topology, 'task: assigned; auto: the network\'s pick'),
      field('objective', 'objective', inputs.objective, 'who lifts, pulls, twists or presses once the grasp is ready'),
      field('hold_s', 'steady hold (s)', inputs.hold_s, 'what the judge asks of a held object (the paper: 5)'),
      field('record', 'record every N episodes', inputs.record_every, 'rerun recording stored with the job (at most 20 episodes)'),
      field('record_connect', 'or stream to a viewer', inputs.record_connect, 'live instead of the file')),
    formError,
    el('button', { type: 'submit' }, 'Submit'));
  show();

  form.addEventListener('submit', async (e) => {
    e.preventDefault();
    form.querySelectorAll('.field-error').forEach((n) => { n.textContent = ''; });
    form.querySelectorAll('.invalid').forEach((n) => n.classList.remove('invalid'));
    const body = { kind: kind.value };
    if (inputs.world.value !== 'crm') body.world = inputs.world.value;
    const number = (name) => {
      const text = inputs[name].value.trim();
      if (text === '') return undefined;
      const value = Number(text);
      return Number.isFinite(value) && text.match(/^-?\d+(\.\d+)?$/) ? value : text;
    };
    const tasks = [...inputs.tasks.selectedOptions].map((o) => o.value);
    if (tasks.length) body.tasks = tasks;
    body.seed = number('seed');
    if (inputs.topology.value !== 'task') body.topology = inputs.topology.value;
    if (inputs.objective.value !== 'scripted') body.objective = inputs.objective.value;
    const hold = number('hold_s');
    if (hold !== undefined) body.hold_s = hold;
    const every = number('record_every');
    const connect = inputs.record_connect.value.trim();
    if (every !== undefined || connect) {
      body.record = { every: every === undefined ? 1 : every };
      if (connect) body.record.connect = connect;
    }
    if (kind.value === 'train') {
      body.algorithm = inputs.algorithm.value;
      body.steps = number('steps');
      body.envs = number('envs');
      const imitation = number('imitation');
      if (imitation !== undefined) body.imitation = { episodes: imitation };
      if (inputs.curriculum.checked) body.curriculum = true;
      const text = inputs.config.value.trim();
      if (text) {
        try {
          const config = JSON.parse(text);
          if (body.algorithm === 'crm-sac' && !config.sac) body.sac = config;
          else if (config.sac) { body.sac = config.sac; delete config.sac; if (Object.keys(config).length) body.config = config; }
          else body.config = config;
        } catch (err) {
          return showError(form, formError, { field: 'config', message: `not JSON: ${err.message}` });
        }
      }
    } else {
      body.checkpoint_id = number('checkpoint_id');
      body.episodes = number('episodes');
    }
    try {
      const job = await send('POST', '/api/v1/jobs', body);
      onQueued(job.job || job);
    } catch (err) {
      showError(form, formError, err);
    }
  });
  return form;
}

/** Puts the API's message beside the field it names (`config.gamma` -> config). */
function showError(form, formError, err) {
  const name = (err.field || '').split(/[.[]/)[0];
  const sub = (err.field || '').split('.')[1];
  const key = name === 'task' ? 'tasks' : name === 'sac' ? 'config'
    : name === 'record' && sub === 'connect' ? 'record_connect' : name;
  const slot = key && form.querySelector(`[data-error-for="${key}"]`);
  const text = err.field ? `${err.field}: ${err.message}` : err.message;
  if (slot && !slot.closest('[hidden]')) {
    slot.textContent = text;
    form.querySelector(`[data-field="${key}"] input, [data-field="${key}"] select, [data-field="${key}"] textarea`)?.classList.add('invalid');
  } else {
    formError.textContent = text;
  }
}
