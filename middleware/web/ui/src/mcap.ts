// What a chart shows, as an MCAP file for Foxglove, Lichtblick or PlotJuggler: laid out as
// `autoplug export --format mcap` lays out a log (one JSON channel per catalogue message,
// `/VehicleSpeedMsg`, its fields the signals by their DBC names, each signal's VSS path
// and unit in the channel's metadata), so a plot's file and a log's open the same way.
// Written with Foxglove's @mcap/core.
import { McapWriter, TempBuffer } from '@mcap/core';
import type { SignalInfo } from './live';

export async function mcapOf(signals: SignalInfo[], rows: [number, (number | null)[]][]): Promise<Uint8Array> {
  const buffer = new TempBuffer();
  const writer = new McapWriter({ writable: buffer });
  await writer.start({ profile: '', library: 'AutoPlug dashboard' });
  const encoder = new TextEncoder();
  // Signals grouped by their message ("Message.Signal").
  const messages = new Map<string, { field: string; column: number; info: SignalInfo }[]>();
  signals.forEach((info, column) => {
    const [message, field] = info.name.split('.', 2);
    const fields = messages.get(message) ?? [];
    fields.push({ field, column, info });
    messages.set(message, fields);
  });
  const channels: { id: number; fields: { field: string; column: number }[] }[] = [];
  for (const [message, fields] of messages) {
    const properties = Object.fromEntries(fields.map(({ field, info }) => [field, { type: 'number', description: `${info.path} [${info.unit}]` }]));
    const schema = await writer.registerSchema({
      name: `autoplug.${message}`,
      encoding: 'jsonschema',
      data: encoder.encode(JSON.stringify({ type: 'object', title: message, properties })),
    });
    const metadata = new Map<string, string>();
    for (const { field, info } of fields) {
      metadata.set(`${field}.vss`, info.path);
      metadata.set(`${field}.unit`, info.unit);
    }
    const id = await writer.registerChannel({ topic: `/${message}`, schemaId: schema, messageEncoding: 'json', metadata });
    channels.push({ id, fields });
  }
  let sequence = 0;
  for (const [t, values] of rows) {
    const time = BigInt(Math.round(t * 1e6)) * 1000n;
    for (const channel of channels) {
      const body: Record<string, number> = {};
      for (const { field, column } of channel.fields) {
        const v = values[column];
        if (v !== null && v !== undefined) body[field] = v;
      }
      if (Object.keys(body).length === 0) continue;
      sequence += 1;
      await writer.addMessage({ channelId: channel.id, sequence, logTime: time, publishTime: time, data: encoder.encode(JSON.stringify(body)) });
    }
  }
  await writer.end();
  return buffer.get();
}
