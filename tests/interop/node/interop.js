// Node ads-client (v2, rawClient: true) against hli-server's ADS door: the second, independent ADS
// client of tests/interop/test_node_ads_client.py (H-04). Prints one JSON object with what it saw.
//
//   node interop.js PORT '{"read": [group, offset, size], "write": [group, offset, hex],
//                          "subscribe": [group, offset, size, cycle_ms], "samples": N, "router": bool}'
//
// router: true connects without a local NetId, so ads-client first asks the server for one (AMS/TCP
// 0x1000 port connect) and sends 0x0001 port close on disconnect; false gives localAmsNetId/Port.
'use strict';
const { Client } = require('ads-client');

async function main() {
  const port = Number(process.argv[2]);
  const job = JSON.parse(process.argv[3]);
  const settings = {
    targetAmsNetId: '127.0.0.1.1.1', targetAdsPort: 851, routerAddress: '127.0.0.1', routerTcpPort: port,
    rawClient: true, autoReconnect: false, timeoutDelay: 3000, hideConsoleWarnings: true,
  };
  if (!job.router) { settings.localAmsNetId = '192.168.1.60.1.1'; settings.localAdsPort = 32750; }
  const client = new Client(settings);
  const out = {};
  const conn = await client.connect();
  out.localAmsNetId = conn.localAmsNetId;
  out.localAdsPort = conn.localAdsPort;
  if (job.write) {
    const [group, offset, hex] = job.write;
    await client.writeRaw(group, offset, Buffer.from(hex, 'hex'));
  }
  if (job.read) {
    const [group, offset, size] = job.read;
    out.read = (await client.readRaw(group, offset, size)).toString('hex');
  }
  if (job.error) {  // a read the server must refuse: the ADS error code ads-client reports
    const [group, offset, size] = job.error;
    try { await client.readRaw(group, offset, size); out.error = 0; } catch (e) {
      out.error = e.adsError ? e.adsError.errorCode : String(e);
    }
  }
  if (job.subscribe) {
    const [group, offset, size, cycleMs] = job.subscribe;
    const samples = [];
    let done;
    const finished = new Promise((resolve) => { done = resolve; });
    const sub = await client.subscribeRaw(group, offset, size, (data) => {
      if (samples.length >= job.samples) return;  // a loaded machine delivers several at once: keep N
      samples.push({ hex: data.value.toString('hex'), time: data.timestamp.toISOString() });
      if (samples.length >= job.samples) done();
    }, cycleMs, false);
    await Promise.race([finished, new Promise((_, no) => setTimeout(() => no(new Error('too few samples')), 10000))]);
    await sub.unsubscribe();
    out.samples = samples;
  }
  await client.disconnect();
  console.log(JSON.stringify(out));
}

main().then(() => process.exit(0), (e) => { console.error(e); process.exit(1); });
