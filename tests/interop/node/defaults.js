// Node ads-client (v2) with its DEFAULT settings against hli-server's ADS door: connect as to a TwinCAT
// (system state on port 10000, the PLC runtime's state, device info, upload info and symbol version on
// 851, notifications on both), then the steps of a job, then disconnect. The only settings given are
// the target and where the router listens (the server's free port): no rawClient, no local NetId.
//
//   node defaults.js PORT '[{"op": "readValue", "path": "..."}, {"op": "writeValue", "path": "...",
//                           "value": ...}, {"op": "subscribeValue", "path": "...", "samples": N,
//                           "cycleTime": ms}, {"op": "getSymbol", "path": "..."},
//                           {"op": "getDataType", "name": "..."}, {"op": "write", "path": ..., "value": ...}]'
//
// Prints one JSON object: {"connection": ..., "results": [...]}; a step that fails gives
// {"error": message, "adsError": code} in its place, and the job goes on.
'use strict';
const { Client } = require('ads-client');

async function step(client, s) {
  switch (s.op) {
    case 'readValue': {
      const r = await client.readValue(s.path);
      return { value: r.value, type: r.dataType.type, size: r.symbol.size };
    }
    case 'writeValue': {
      const r = await client.writeValue(s.path, s.value, s.autoFill === true);
      return { value: r.value };
    }
    case 'getSymbol': {
      const r = await client.getSymbol(s.path);
      return { name: r.name, type: r.type, size: r.size, indexGroup: r.indexGroup, indexOffset: r.indexOffset,
        flags: r.flagsStr };
    }
    case 'getDataType': {
      const r = await client.getDataType(s.name);
      return { type: r.type, size: r.size, subItems: r.subItems.map((i) => [i.name, i.type, i.offset, i.size]),
        arrayInfos: r.arrayInfos };
    }
    case 'subscribeValue': {
      const samples = [];
      let done;
      const finished = new Promise((resolve) => { done = resolve; });
      const sub = await client.subscribeValue(s.path, (data) => {
        if (samples.length >= s.samples) return;  // a loaded machine delivers several at once: keep N
        samples.push({ value: data.value, time: data.timestamp.toISOString() });
        if (samples.length >= s.samples) done();
      }, s.cycleTime ?? 10, s.sendOnChange ?? true);
      const timer = new Promise((_, no) => setTimeout(() => no(new Error(`only ${samples.length} samples`)), 8000));
      await Promise.race([finished, timer]);
      await sub.unsubscribe();
      return { samples };
    }
    default:
      throw new Error(`unknown step ${s.op}`);
  }
}

async function main() {
  const port = Number(process.argv[2]);
  const job = JSON.parse(process.argv[3]);
  const client = new Client({
    targetAmsNetId: '127.0.0.1.1.1', targetAdsPort: 851, routerAddress: '127.0.0.1', routerTcpPort: port,
  });
  const conn = await client.connect();
  // the PLC runtime's state comes by the notification ads-client adds on connect (0xF100); its first
  // sample follows the add response by first_sample_delay_ms, so a loaded machine may finish connect()
  // before it is there: wait for it as a program that reads metaData would
  for (let i = 0; i < 200 && client.metaData.plcRuntimeState === undefined; i++) {
    await new Promise((resolve) => setTimeout(resolve, 10));
  }
  const out = { connection: { localAmsNetId: conn.localAmsNetId, localAdsPort: conn.localAdsPort,
    tcSystemState: client.metaData.tcSystemState, plcRuntimeState: client.metaData.plcRuntimeState,
    deviceInfo: client.metaData.plcDeviceInfo, uploadInfo: client.metaData.plcUploadInfo,
    symbolVersion: client.metaData.plcSymbolVersion }, results: [] };
  for (const s of job) {
    try {
      out.results.push(await step(client, s));
    } catch (e) {
      let cause = e;
      while (cause && !cause.adsError && cause.parent) cause = cause.parent;
      out.results.push({ error: e.message, adsError: cause && cause.adsError ? cause.adsError.errorCode : null });
    }
  }
  await client.disconnect();
  console.log(JSON.stringify(out, (key, value) => (typeof value === 'bigint' ? value.toString() : value)));
}

main().then(() => process.exit(0), (e) => { console.error(e); process.exit(1); });
