// Fleet: the manufacturer's side. Every update campaign with its totals (how many vehicles
// in each state, its stage, why it paused), and one campaign per vehicle: its stage, state,
// attempts, the version its ECU now runs and the reason it gave. Read from the fleet
// database (`--fleet-db`, or `autoplug fleet serve --web`), refreshed every 2 s.
import { get } from '../api';
import type { Ctx, View } from '../view';
import { h, num, setText, utc } from '../util';

const STATES = ['waiting', 'sent', 'received', 'installing', 'installed', 'declined', 'refused', 'failed', 'unanswered'];
const GOOD = new Set(['installed']);
const BAD = new Set(['refused', 'failed', 'unanswered']);

function stateCell(state: string): HTMLElement {
  return h('span', { class: `badge ${GOOD.has(state) ? 'ok' : BAD.has(state) ? 'bad' : state === 'declined' ? 'warn' : 'neutral'}`, text: state });
}

/** A bar of the vehicles per state, in campaign order. */
function bar(counts: Record<string, number>, total: number): HTMLElement {
  const el = h('div', { class: 'fleet-bar', role: 'img', 'aria-label': Object.entries(counts).map(([k, v]) => `${v} ${k}`).join(', ') });
  for (const state of STATES) {
    const n = counts[state] ?? 0;
    if (n > 0) el.append(h('span', { class: `seg ${state}`, style: `flex-grow:${n}`, title: `${n} ${state}` }));
  }
  if (total === 0) el.append(h('span', { class: 'seg waiting', style: 'flex-grow:1' }));
  return el;
}

export function fleetView(_ctx: Ctx): View {
  const summary = h('div', { class: 'fleet-summary', 'data-testid': 'fleet-summary' });
  const list = h('tbody', { 'data-testid': 'fleet-campaigns' });
  const detail = h('div', { class: 'card table-wrap', hidden: true, 'data-testid': 'fleet-campaign' });
  const source = h('span', { class: 'muted small' });
  const el = h('section', { class: 'fleet' },
    h('div', { class: 'card' }, h('h3', {}, 'Fleet ', source), summary),
    h('div', { class: 'card table-wrap' }, h('h3', { text: 'Update campaigns' }),
      h('table', { class: 'grid' }, h('thead', {}, h('tr', {}, ...['#', 'Name', 'ECU', 'Version', 'State', 'Stage', 'Vehicles', '', 'Created'].map((t) => h('th', { text: t })))), list)),
    detail,
  );
  let selected: number | null = null;
  let timer: number | undefined;

  async function load(): Promise<void> {
    try {
      const data = await get('/api/fleet');
      setText(source, data.fleet);
      const s = data.summary;
      summary.replaceChildren(...[
        ['Vehicles', String(s.vehicles)], ['Trips', String(s.trips)], ['Distance', `${num(s.distance_km, 1)} km`], ['Faulty verdicts', String(s.faulty_verdicts)],
      ].map(([k, v]) => h('div', { class: 'stat' }, h('div', { class: 'muted small', text: k }), h('div', { class: 'value', text: v }))));
      const campaigns: any[] = data.campaigns;
      list.replaceChildren(...campaigns.map((c) => {
        const installed = c.counts.installed ?? 0;
        const tr = h('tr', { class: `clickable${c.id === selected ? ' selected' : ''}`, tabindex: 0, 'data-testid': `campaign-${c.id}` },
          h('td', { text: String(c.id) }), h('td', { text: c.name }), h('td', { text: c.ecu }), h('td', { class: 'mono', text: c.version }),
          h('td', {}, h('span', { class: `badge ${c.state === 'finished' ? 'ok' : c.state === 'paused' ? 'bad' : 'neutral'}`, text: c.state, title: c.paused_reason ?? '' })),
          h('td', { text: `${c.stage + 1} of ${c.stages.length} (${c.stages.map((p: number) => `${p}%`).join(' → ')})` }),
          h('td', { text: `${installed} / ${c.vehicles} installed` }),
          h('td', { class: 'bar-cell' }, bar(c.counts, c.vehicles)),
          h('td', { text: utc(c.created_at_ms) }));
        tr.addEventListener('click', () => { selected = c.id; void load(); });
        tr.addEventListener('keydown', (e) => { if (e.key === 'Enter') { selected = c.id; void load(); } });
        return tr;
      }));
      if (campaigns.length === 0) list.append(h('tr', {}, h('td', { colspan: 9, class: 'muted', text: 'No campaign yet: autoplug fleet campaign create …' })));
      if (selected === null && campaigns.length > 0) selected = campaigns[0].id;
      if (selected !== null) await showCampaign(selected);
    } catch (e: any) {
      summary.replaceChildren(h('p', { class: 'muted', text: e.message }));
    }
  }

  async function showCampaign(id: number): Promise<void> {
    const d = await get(`/api/fleet/campaigns/${id}`);
    const c = d.campaign;
    const vehicles: any[] = d.vehicles;
    const counts = STATES.filter((s) => c.counts[s]).map((s) => `${c.counts[s]} ${s}`).join(' · ');
    detail.hidden = false;
    detail.replaceChildren(
      h('h3', { text: `Campaign ${c.id}: ${c.name}` }),
      h('p', { class: 'small' }, `${c.ecu} ${c.version} to ${c.vehicles} vehicle${c.vehicles === 1 ? '' : 's'} · ${counts || 'none yet'}`,
        c.paused_reason ? h('span', { class: 'bad-text', text: ` · paused: ${c.paused_reason}` }) : ''),
      h('table', { class: 'grid', 'data-testid': 'fleet-vehicles' },
        h('thead', {}, h('tr', {}, ...['VIN', 'Stage', 'State', 'Attempts', 'Running', 'Reason', 'Updated'].map((t) => h('th', { text: t })))),
        h('tbody', {}, ...vehicles.map((v) => h('tr', { 'data-vin': v.vin },
          h('td', { class: 'mono', text: v.vin }), h('td', { text: String(v.stage + 1) }), h('td', {}, stateCell(v.state)),
          h('td', { text: String(v.attempts) }), h('td', { class: 'mono', text: v.version_running ?? '–' }),
          h('td', { class: 'small', text: v.reason ?? '' }), h('td', { text: utc(v.updated_at_ms) }))))),
    );
  }

  void load();
  timer = window.setInterval(() => void load(), 2000);
  return {
    el,
    update() {},
    destroy() { window.clearInterval(timer); },
  };
}
