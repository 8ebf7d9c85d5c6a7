"""The monitor's live view: a local web page with each unit's H and its interval over time.

``GET /`` is one self-contained page (no script or style from elsewhere) that asks for
``/state.json`` every second and draws, per unit, H with its 95 % band over the last
``HISTORY`` updates (dots coloured by the window's verdict; a grey gap where a window did not
excite H), the latest value with its interval, D, the estimate's age and the alarm, and above
them the streams' frames used, grid slots without a frame, late frames, disconnects and the
delay from a frame's timestamp to its estimate in stream time (and in wall time where a stream
does not run in real time). With ``[inertia]``, a panel per area and for the system above
the units: the stored kinetic energy E [GW s] over the last ``HISTORY`` lines with its 95 %
band, the commitment figure (dashed), the configured floor (red line) and, while E is below
the floor, the alarm (the panel framed red, "BELOW FLOOR"). The server binds 127.0.0.1 unless
told otherwise and answers only those two paths.
"""

from __future__ import annotations

import json
import threading
from collections import deque
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

HISTORY = 600
"""Updates kept per unit for the page (10 minutes at one a second)."""

PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>jaxdse monitor</title>
<style>
body{font-family:system-ui,sans-serif;margin:16px;color:#222;background:#fafafa}
h1{font-size:20px;margin:0 0 4px}
#status{font-size:13px;color:#555;margin-bottom:12px}
.grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(330px,1fr));gap:10px}
.unit{background:#fff;border:1px solid #ddd;border-radius:6px;padding:8px}
.unit.alarm{border:2px solid #c62828}
.name{font-weight:600}
.badge{display:inline-block;padding:1px 6px;border-radius:8px;color:#fff;font-size:12px;margin-left:6px}
.v{font-size:13px;margin:2px 0}
svg{width:100%;height:90px}
.legend{font-size:12px;color:#555;margin:8px 0}
</style></head><body>
<h1>jaxdse monitor: inertia H per unit</h1>
<div id="status">waiting for data...</div>
<div class="legend">Each panel: H [s] (dots, coloured by the window's verdict) with its 95 % interval
(band) over the last updates; grey ticks: windows that did not excite H (no value).
<span class="badge" style="background:#2e7d32">identified</span>
<span class="badge" style="background:#f9a825">weakly identified</span>
<span class="badge" style="background:#9e9e9e">not excited</span>
<span class="badge" style="background:#c62828">failed</span></div>
<div class="grid" id="inertia"></div>
<div class="grid" id="grid"></div>
<script>
const COLOURS={"identified":"#2e7d32","weakly identified":"#f9a825","not excited":"#9e9e9e","failed":"#c62828"};
function fmt(x,d){return x===null||x===undefined||!isFinite(x)?"-":x.toFixed(d)}
function utc(t){return new Date(t*1000).toISOString().replace("T"," ").slice(0,19)+" UTC"}
function chart(h){
  const W=320,Hh=90,pts=h.filter(p=>p.H!==null);
  if(!h.length)return "<svg></svg>";
  const t0=h[0].t,t1=Math.max(h[h.length-1].t,t0+1);
  let lo=Infinity,hi=-Infinity;
  for(const p of pts){lo=Math.min(lo,isFinite(p.lo)?p.lo:p.H);hi=Math.max(hi,isFinite(p.hi)?p.hi:p.H)}
  if(!pts.length){lo=0;hi=1}
  const pad=0.1*(hi-lo||1);lo-=pad;hi+=pad;
  const X=t=>4+(W-8)*(t-t0)/(t1-t0),Y=v=>Hh-14-(Hh-20)*(v-lo)/(hi-lo);
  let band="",top=[],bot=[];
  for(const p of pts){if(isFinite(p.lo)&&isFinite(p.hi)){top.push(X(p.t)+","+Y(p.hi));bot.unshift(X(p.t)+","+Y(p.lo))}}
  if(top.length)band=`<polygon points="${top.concat(bot).join(" ")}" fill="#90caf9" opacity="0.45"/>`;
  let dots="";
  for(const p of h){
    if(p.H===null)dots+=`<line x1="${X(p.t)}" x2="${X(p.t)}" y1="${Hh-12}" y2="${Hh-6}" stroke="#bbb"/>`;
    else dots+=`<circle cx="${X(p.t)}" cy="${Y(p.H)}" r="1.8" fill="${COLOURS[p.verdict]||"#000"}"/>`;
  }
  const axis=`<text x="2" y="10" font-size="10" fill="#555">${fmt(hi,2)} s</text>`+
             `<text x="2" y="${Hh-16}" font-size="10" fill="#555">${fmt(lo,2)} s</text>`+
             `<text x="${W-4}" y="${Hh-1}" font-size="10" fill="#555" text-anchor="end">${utc(t1).slice(11)}</text>`;
  return `<svg viewBox="0 0 ${W} ${Hh}">${band}${dots}${axis}</svg>`;
}
function echart(h,floor){
  const W=320,Hh=110;
  if(!h.length)return "<svg></svg>";
  const t0=h[0].t,t1=Math.max(h[h.length-1].t,t0+1);
  let lo=Infinity,hi=-Infinity;
  for(const p of h){for(const v of [p.E,p.lo,p.hi,p.com]){if(v!==null&&isFinite(v)){lo=Math.min(lo,v);hi=Math.max(hi,v)}}}
  if(floor!==null&&floor!==undefined){lo=Math.min(lo,floor);hi=Math.max(hi,floor)}
  if(!isFinite(lo)){lo=0;hi=1}
  const pad=0.1*(hi-lo||Math.abs(hi)||1);lo-=pad;hi+=pad;
  const X=t=>4+(W-8)*(t-t0)/(t1-t0),Y=v=>Hh-14-(Hh-20)*(v-lo)/(hi-lo);
  let top=[],bot=[],e=[],c=[];
  for(const p of h){
    if(p.lo!==null&&p.hi!==null){top.push(X(p.t)+","+Y(p.hi));bot.unshift(X(p.t)+","+Y(p.lo))}
    if(p.E!==null)e.push(X(p.t)+","+Y(p.E));
    if(p.com!==null)c.push(X(p.t)+","+Y(p.com));
  }
  let g=top.length?`<polygon points="${top.concat(bot).join(" ")}" fill="#90caf9" opacity="0.45"/>`:"";
  if(c.length)g+=`<polyline points="${c.join(" ")}" fill="none" stroke="#6d4c41" stroke-dasharray="4 3"/>`;
  if(e.length)g+=`<polyline points="${e.join(" ")}" fill="none" stroke="#0d47a1" stroke-width="1.6"/>`;
  if(floor!==null&&floor!==undefined)g+=`<line class="floor" x1="4" x2="${W-4}" y1="${Y(floor)}" y2="${Y(floor)}" stroke="#c62828"/>`;
  g+=`<text x="2" y="10" font-size="10" fill="#555">${fmt(hi/1e3,3)} GW s</text>`+
     `<text x="2" y="${Hh-16}" font-size="10" fill="#555">${fmt(lo/1e3,3)} GW s</text>`+
     `<text x="${W-4}" y="${Hh-1}" font-size="10" fill="#555" text-anchor="end">${utc(t1).slice(11)}</text>`;
  return `<svg viewBox="0 0 ${W} ${Hh}" style="height:110px">${g}</svg>`;
}
function inertia(s){
  const el=document.getElementById("inertia"),x=s.inertia;
  if(!x){el.innerHTML="";return}
  el.innerHTML=x.areas.map(a=>{
    const l=a.latest||{},alarm=!!l.below_floor;
    return `<div class="unit${alarm?" alarm":""}" data-area="${a.area}"><span class="name">E ${a.area}</span>`+
      (alarm?'<span class="badge" style="background:#c62828">BELOW FLOOR</span>':"")+
      `<div class="v">E <b>${fmt(l.E_MWs/1e3,3)} GW s</b> (95 %: ${l.E_ci95?fmt(l.E_ci95[0]/1e3,3)+" - "+fmt(l.E_ci95[1]/1e3,3):"-"}), `+
      `commitment ${fmt(l.E_commitment_MWs/1e3,3)}, floor ${x.floor_MWs===null?"-":fmt(x.floor_MWs/1e3,3)} GW s, `+
      `measured ${fmt(100*l.measured_share,0)} % (${l.units_measured??"-"} of ${l.units_online??"-"} online), `+
      `RoCoF ${fmt(l.rocof_hz_per_s,3)} Hz/s</div>`+echart(a.history,x.floor_MWs)+"</div>"}).join("")+
    `<div class="legend">E: line, 95 % band; dashed: commitment figure (every online unit at its .dyr H); red: floor.</div>`;
}
async function tick(){
  let s;
  try{s=await (await fetch("state.json",{cache:"no-store"})).json()}catch(e){return}
  const d=s.delay_s,w=s.wall_delay_s;
  const slow=s.streams.some(x=>x.pace&&Math.abs(x.pace-1)>0.01);
  document.getElementById("status").textContent=
    (s.t?utc(s.t)+" | ":"")+s.units.length+" unit(s) | "+s.streams.map(x=>`stream ${x.stream} ${x.host}:${x.port}: frames used ${x.frames_used||0}, grid slots without a frame ${x.slots_without_frame||0}, late frames ${x.late_frames||0}, disconnects ${x.disconnects||0}`+(x.pace&&Math.abs(x.pace-1)>0.01?`, at ${fmt(x.pace,2)}x real time`:"")).join("; ")+
    (d?` | delay frame to estimate: median ${fmt(d.median,2)} s, 99 % ${fmt(d.p99,2)} s of stream time`+(slow&&w?` (${fmt(w.median,2)} s, ${fmt(w.p99,2)} s of wall time)`:""):"");
  inertia(s);
  document.getElementById("grid").innerHTML=s.units.map(u=>{
    const l=u.latest||{},c=COLOURS[l.verdict]||"#555";
    return `<div class="unit${l.alarm?" alarm":""}" data-unit="${u.unit}"><span class="name">${u.unit}</span>`+
      `<span class="badge" style="background:${c}">${l.verdict||"waiting"}</span>${l.alarm?'<span class="badge" style="background:#c62828">H ALARM</span>':""}`+
      `<div class="v">H <b>${fmt(l.H_s,2)} s</b> (95 %: ${l.H_ci95?fmt(l.H_ci95[0],2)+" - "+fmt(l.H_ci95[1],2):"-"} s), D ${fmt(l.D,3)}, `+
      `age ${fmt(l.age_s,0)} s${l.H_s===null&&l.last_H_s!==null&&l.last_H_s!==undefined?", last identified "+fmt(l.last_H_s,2)+" s":""}</div>`+
      chart(u.history)+"</div>"}).join("");
}
tick();setInterval(tick,1000);
</script></body></html>
"""


class LiveView:
    """Keeps each unit's recent updates and serves the page (see the module docstring)."""

    def __init__(self, units: list[str], status, host: str = "127.0.0.1", port: int = 8050,
                 floor_MWs: float | None = None):
        self.units = list(units)
        self.floor_MWs = floor_MWs
        """The system inertia's floor [MW s] (``[inertia] floor_MWs``), drawn on its panels."""
        self.areas: dict = {}
        """Area -> its recent system inertia lines (empty without ``[inertia]``)."""
        self.status = status
        """Called (from the server's thread) for the streams' counts and the delay: a dict."""
        self.history = {u: deque(maxlen=HISTORY) for u in self.units}
        self.latest = {}
        self.lock = threading.Lock()
        self.host, self.port = host, port
        self.server = None
        self.bound = None

    def add(self, line: dict):
        """One line of ``updates.jsonl``."""
        with self.lock:
            lo, hi = line["H_ci95"] or (None, None)
            self.history.setdefault(line["unit"], deque(maxlen=HISTORY)).append(
                {"t": line["t"], "H": line["H_s"], "lo": lo, "hi": hi, "verdict": line["verdict"]})
            self.latest[line["unit"]] = line

    def add_inertia(self, lines: list[dict]):
        """The system inertia's lines of one update (one per area and the system's)."""
        with self.lock:
            for x in lines:
                lo, hi = x["E_ci95"]
                self.areas.setdefault(x["area"], {"history": deque(maxlen=HISTORY), "latest": None})
                self.areas[x["area"]]["history"].append({"t": x["t"], "E": x["E_MWs"], "lo": lo, "hi": hi,
                                                         "com": x["E_commitment_MWs"]})
                below = None if self.floor_MWs is None else bool(x["E_MWs"] < self.floor_MWs)
                self.areas[x["area"]]["latest"] = {**x, "below_floor": below}

    def state(self) -> dict:
        with self.lock:
            units = [{"unit": u, "latest": self.latest.get(u), "history": list(h)} for u, h in self.history.items()]
            t = max((x["t"] for x in self.latest.values()), default=None)
            inertia = None if not self.areas else {
                "floor_MWs": self.floor_MWs,
                "areas": [{"area": a, "latest": v["latest"], "history": list(v["history"])}
                          for a, v in self.areas.items()]}
        return {"t": t, "units": units, "inertia": inertia, **self.status()}

    def start(self):
        view = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self):
                if self.path in ("/", "/index.html"):
                    body, kind = PAGE.encode(), "text/html; charset=utf-8"
                elif self.path.startswith("/state.json"):
                    body = json.dumps(_finite(view.state()), allow_nan=False).encode()
                    kind = "application/json"
                else:
                    self.send_error(404)
                    return
                self.send_response(200)
                self.send_header("Content-Type", kind)
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Cache-Control", "no-store")
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args):
                pass

        self.server = ThreadingHTTPServer((self.host, self.port), Handler)
        self.server.daemon_threads = True
        self.bound = self.server.server_address[:2]
        threading.Thread(target=self.server.serve_forever, daemon=True, name="jaxdse-view").start()
        return self.bound

    def stop(self):
        if self.server is not None:
            self.server.shutdown()
            self.server.server_close()


def _finite(x):
    """``x`` with every non-finite float as None (JSON has no NaN or infinity)."""
    if isinstance(x, float):
        return x if x == x and abs(x) != float("inf") else None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    return x
