// The fleet's update offer, on every view: the driver's question ("An update for your
// cruise control is ready: install when parked?") with its two answers, then where the
// update stands until the vehicle's report. Sized for a phone: the driver answers it there.
import { post } from './api';
import type { Live } from './live';
import { bytes, h, setText } from './util';

const ACTIVITY: Record<string, string> = {
  'fetching the image': 'Fetching the update…',
  'asking the driver': 'Waiting for your answer',
  'waiting for the car to stand still': 'Will install when the car is parked',
  flashing: 'Installing — keep the car parked',
  'checking the new version': 'Checking the new version…',
};

export function offerBanner(live: Live, toast: (text: string, kind?: 'ok' | 'error') => void): { el: HTMLElement; update(): void } {
  const question = h('p', { class: 'offer-question', 'data-testid': 'offer-question' });
  const detail = h('p', { class: 'muted small', 'data-testid': 'offer-detail' });
  const install = h('button', { class: 'btn primary big', 'data-testid': 'offer-install', text: 'Install when parked' });
  const later = h('button', { class: 'btn big', 'data-testid': 'offer-decline', text: 'Not now' });
  const buttons = h('div', { class: 'offer-buttons' }, install, later);
  const state = h('p', { class: 'offer-state', 'data-testid': 'offer-state', role: 'status' });
  const el = h('section', { class: 'offer', 'data-testid': 'offer', hidden: true, 'aria-label': 'software update' },
    h('div', { class: 'offer-title', text: 'Software update' }), question, detail, buttons, state);
  // The campaign last answered, so the buttons do not come back while the answer travels.
  let answered: number | null = null;
  // The last report shown, so a finished update stays on screen until dismissed.
  let finished: string | null = null;
  let dismissed: string | null = null;
  let lastOffer: NonNullable<NonNullable<Live['session']>['fleet']>['offer'] = null;
  const dismiss = h('button', { class: 'btn', 'data-testid': 'offer-dismiss', text: 'OK' });
  dismiss.addEventListener('click', () => { dismissed = finished; update(); });

  async function answer(install: boolean): Promise<void> {
    const offer = live.session?.fleet?.offer;
    if (!offer) return;
    answered = offer.campaign;
    update();
    try {
      await post('/api/fleet/consent', { campaign: offer.campaign, install });
      toast(install ? 'The update installs when the car is parked' : 'Update declined');
    } catch (e: any) {
      answered = null;
      toast(e.message, 'error');
      update();
    }
  }
  install.addEventListener('click', () => void answer(true));
  later.addEventListener('click', () => void answer(false));

  function update(): void {
    const fleet = live.session?.fleet;
    const offer = fleet?.offer ?? null;
    const activity = fleet?.activity ?? null;
    const last = fleet?.reports.length ? fleet.reports[fleet.reports.length - 1] : null;
    const final = last && ['installed', 'refused', 'failed'].includes(last.state) ? `${last.campaign}:${last.state}:${last.at_ms}` : null;
    if (final && !activity) finished = final;
    const showFinished = !offer && !activity && finished !== null && finished !== dismissed && last !== null;
    el.hidden = !offer && !activity && !showFinished;
    if (el.hidden) return;
    if (offer) lastOffer = offer;
    if (offer) {
      setText(question, offer.question);
      setText(detail, `${offer.ecu} ${offer.version} · ${bytes(offer.bytes)}${offer.message ? ` · ${offer.message}` : ''}`);
    } else if (showFinished && last) {
      setText(question, last.state === 'installed' ? `Your ${last.ecu} software is up to date` : `The ${last.ecu} update did not install`);
      setText(detail, `now running ${last.version_running ?? '?'}${last.reason ? ` · ${last.reason}` : ''}`);
    } else if (activity) {
      const known = lastOffer?.campaign === activity.campaign ? lastOffer : null;
      setText(question, known ? `Updating your ${known.ecu} to ${known.version}` : 'A software update is under way');
      setText(detail, known ? `${bytes(known.bytes)}${known.message ? ` · ${known.message}` : ''}` : '');
    }
    const asking = offer !== null && activity?.what === 'asking the driver' && answered !== offer.campaign;
    buttons.hidden = !asking;
    el.classList.toggle('done', showFinished && last?.state === 'installed');
    el.classList.toggle('bad', showFinished && last?.state !== 'installed');
    if (showFinished) {
      state.replaceChildren(dismiss);
    } else if (activity && !asking) {
      const parked = fleet?.standing ? '' : ' (the car is moving)';
      const text = ACTIVITY[activity.what] ?? activity.what;
      state.replaceChildren(text + (activity.what === 'waiting for the car to stand still' ? parked : ''));
    } else {
      state.replaceChildren();
    }
  }
  return { el, update };
}
