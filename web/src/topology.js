// Topology choices: per task, the selection network's probabilities and pick beside the
// paper's assigned topology; a heat map of success per objective and topology from
// evaluations with a forced topology.
import { el, errorBox, fmtNum, getJson, onChange } from './api.js';

export async function renderTopology(main) {
  document.title = 'Topologies · crm-grasp';
  const heat = el('div');
  const tasks = el('div');
  const params = new URLSearchParams(window.location.search);
  let checkpoint = params.get('checkpoint_id') || '';
  const picker = el('select', {
    name: 'checkpoint',
    onchange: (e) => {
      checkpoint = e.target.value;
      window.history.replaceState(null, '', checkpoint ? `/topology?checkpoint_id=${checkpoint}` : '/topology');
      refresh();
    },
  });
  main.replaceChildren(el('h1', {}, 'Grasp topology choices'), el('p', { class: 'summary' }),
    el('div', { class: 'toolbar' }, el('label', {}, 'evaluations of ', picker)), heat, tasks);

  async function refresh() {
    let data;
    try {
      data = await getJson(`/api/v1/topology${checkpoint ? `?checkpoint_id=${encodeURIComponent(checkpoint)}` : ''}`);
    } catch (err) {
      heat.replaceChildren(errorBox(err));
      return;
    }
    picker.replaceChildren(el('option', { value: '' }, 'every checkpoint'),
      ...data.checkpoints.map((c) => el('option', { value: c.checkpoint_id, selected: String(c.checkpoint_id) === checkpoint },
        `checkpoint ${c.checkpoint_id} (${c.forced_evaluations} forced-topology evaluations)`)));
    main.querySelector('.summary').textContent =
      `The selection network (${data.model}) picks the assigned topology for ${data.picked_as_assigned} of ${data.tasks.length} tasks.`;
    heat.replaceChildren(heatMap(data));
    tasks.replaceChildren(taskTable(data));
  }
  refresh();
  onChange(refresh);
}

function color(rate) {
  // Red (0) to green (1), light enough for dark text.
  return `hsl(${Math.round(120 * rate)}, 65%, ${82 - 20 * rate}%)`;
}

function heatMap(data) {
  const columns = [...data.topologies, 'task', 'auto'];
  const names = { task: 'assigned', auto: 'network pick' };
  const cell = Object.fromEntries(data.results.map((r) => [`${r.objective}|${r.topology}`, r]));
  const table = el('table', { id: 'heatmap', class: 'heatmap' },
    el('thead', {}, el('tr', {}, el('th', {}, 'objective'), columns.map((t) => el('th', {}, names[t] || t)))),
    el('tbody', {}, data.objectives.map((o) => el('tr', {}, el('th', {}, o), columns.map((t) => {
      const r = cell[`${o}|${t}`];
      return r
        ? el('td', { style: `background:${color(r.success_rate)}`, title: `${r.episodes} episodes in ${r.evaluations} evaluation(s)`, 'data-cell': `${o}|${t}` },
          fmtNum(r.success_rate), el('small', {}, ` n=${r.episodes}`))
        : el('td', { class: 'empty', 'data-cell': `${o}|${t}` }, '–');
    })))));
  return el('section', {},
    el('h2', {}, 'Success per objective and topology'),
    el('p', { class: 'muted' }, data.results.length
      ? 'From finished evaluations; "assigned" and "network pick" are evaluations without a forced topology.'
      : 'No evaluation yet. Submit eval jobs with a topology forced (the form\'s topology field) to fill this map.'),
    table);
}

function taskTable(data) {
  return el('section', {},
    el('h2', {}, 'The network\'s pick per task'),
    el('table', { id: 'topology-tasks' },
      el('thead', {}, el('tr', {}, ['task', 'objective', 'assigned', 'network pick', ...data.topologies].map((h) => el('th', {}, h)))),
      el('tbody', {}, data.tasks.map((t) => el('tr', { 'data-task': t.task, class: t.picked === t.assigned ? '' : 'disagree' },
        el('td', {}, t.task), el('td', {}, t.objective), el('td', {}, t.assigned),
        el('td', { class: t.picked === t.assigned ? 'ok' : 'bad' }, `${t.picked} ${t.picked === t.assigned ? '✓' : '✗'}`),
        data.topologies.map((name) => {
          const p = t.probabilities[name] || 0;
          return el('td', { class: `prob${name === t.picked ? ' picked' : ''}${name === t.assigned ? ' assigned' : ''}` },
            el('div', { class: 'pbar', style: `width:${Math.round(100 * p)}%` }), el('span', {}, fmtNum(p)));
        }))))));
}
