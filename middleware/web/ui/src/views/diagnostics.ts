// Diagnostics: each ECU's verdict with its number, thresholds and explanation, and the
// trouble codes the ECUs reported, with their descriptions; clear them.
import { post } from '../api';
import type { Ctx, View } from '../view';
import { h, num, setText } from '../util';

export function diagnosticsView(ctx: Ctx): View {
  const { live } = ctx;
  const verdicts = h('tbody');
  const codes = h('div', { class: 'dtc-list' });
  const clearAll = h('button', { class: 'btn danger', 'data-testid': 'clear-dtcs' }, 'Clear all DTCs');
  clearAll.addEventListener('click', async () => {
    clearAll.setAttribute('disabled', '');
    try {
      await post('/api/ecus/all/clear-dtcs');
      ctx.toast('Clearing the trouble codes of all ECUs…');
    } catch (e: any) {
      ctx.toast(e.message, 'error');
    } finally {
      clearAll.removeAttribute('disabled');
    }
  });
  const el = h('section', { class: 'diagnostics' },
    h('div', { class: 'card table-wrap' }, h('h3', { text: 'Verdicts (from the bus alone)' }),
      h('table', { class: 'grid' },
        h('thead', {}, h('tr', {}, ...['ECU', 'Verdict', 'Number', 'Suspect / faulty above', 'Routine', 'Evidence', ''].map((t) => h('th', { text: t })))),
        verdicts)),
    h('div', { class: 'card' }, h('div', { class: 'toolbar' }, h('h3', { text: 'Trouble codes (UDS 0x19)' }), clearAll), codes),
  );
  const rows = new Map<string, HTMLElement[]>();
  let lastCodes = '';

  function update(): void {
    const s = live.session;
    if (!s) return;
    for (const d of s.diagnostics) {
      let cells = rows.get(d.ecu);
      if (!cells) {
        cells = [0, 1, 2, 3, 4, 5, 6].map(() => h('td'));
        // Judge this ECU again from now on: a verdict that no longer holds (the fault
        // fixed, or judged in a moment that proves nothing) does not stay forever.
        const ecu = d.ecu;
        const reset = h('button', { class: 'btn small', 'data-testid': `reset-verdict-${ecu}`, title: 'the gateway\'s routines for this ECU start over', text: 'Reset' });
        reset.addEventListener('click', async () => {
          try {
            // The session's event says so, on every open page.
            await post(`/api/ecus/${ecu}/reset-verdict`);
          } catch (e: any) {
            ctx.toast(e.message, 'error');
          }
        });
        cells[6].append(reset);
        verdicts.append(h('tr', { 'data-testid': `verdict-${d.ecu}` }, ...cells));
        rows.set(d.ecu, cells);
      }
      setText(cells[0], d.ecu);
      const badge = cells[1];
      setText(badge, d.verdict);
      badge.className = `verdict v-${d.verdict.replace(/\s+/g, '-')}`;
      badge.dataset.verdict = d.verdict;
      setText(cells[2], d.number === null ? '–' : `${num(d.number, 3)} ${d.unit ?? ''}`);
      cells[2].dataset.number = d.number === null ? '' : String(d.number);
      setText(cells[3], d.suspect_above === null ? '–' : `${d.suspect_above} / ${d.faulty_above} ${d.unit ?? ''}`);
      setText(cells[4], d.routine ?? '–');
      setText(cells[5], d.evidence ?? '');
    }
    const text = JSON.stringify(s.dtcs);
    if (text === lastCodes) return;
    lastCodes = text;
    codes.replaceChildren();
    if (!s.source.transmit) {
      codes.append(h('p', { class: 'muted', text: 'The gateway only listens on this bus: codes appear when another tester reads them.' }));
    }
    if (s.dtcs.length === 0) codes.append(h('p', { class: 'muted', text: 'No reading of the trouble codes yet.' }));
    for (const report of s.dtcs) {
      const clear = h('button', { class: 'btn small', text: 'Clear' });
      clear.addEventListener('click', async () => {
        try {
          await post(`/api/ecus/${report.ecu}/clear-dtcs`);
          ctx.toast(`Clearing the trouble codes of ${report.ecu}…`);
        } catch (e: any) {
          ctx.toast(e.message, 'error');
        }
      });
      codes.append(h('div', { class: 'dtc-ecu', 'data-testid': `dtcs-${report.ecu}` },
        h('div', { class: 'toolbar' }, h('strong', { text: report.ecu }), h('span', { class: 'muted small', text: `read at ${num(report.read_at, 1)} s` }), report.codes.length ? clear : null),
        report.codes.length === 0
          ? h('div', { class: 'muted small', text: 'none' })
          : h('ul', {}, ...report.codes.map((c) => h('li', {}, h('code', { text: c.code }), ` status 0x${c.status.toString(16).toUpperCase().padStart(2, '0')}: ${c.description}`)))));
    }
  }
  return { el, update };
}
