// swarmpark replay: a timeline (play, pause, seek, speed) over the live UI (app.js), which
// draws the recorded frames exactly as it draws a run. Loaded only by `swarmpark replay`
// (the replay server adds this script to index.html); the controls talk to /api/replay.
"use strict";

(function replay() {
  const R = { status: null, dragging: false };
  const el = (tag, attrs = {}, text = "") => {
    const e = document.createElement(tag);
    Object.entries(attrs).forEach(([k, v]) => e.setAttribute(k, v));
    if (text) e.textContent = text;
    return e;
  };

  // Nothing can be commanded in a replay: hide the operator's controls.
  for (const id of ["estop", "resume-all", "park-box", "scenario-load", "scenario-scripted"]) {
    const e = document.getElementById(id);
    if (e) (e.closest("label") || e).classList.add("hidden");
  }
  const simGroup = document.getElementById("sim-pause");
  if (simGroup) simGroup.parentElement.classList.add("hidden");
  document.querySelector("#topbar .brand").textContent = "swarmpark replay";

  const bar = el("div", { id: "replay-bar" });
  bar.style.cssText = "position:absolute;left:8px;right:8px;bottom:8px;display:flex;gap:8px;" +
    "align-items:center;padding:6px 10px;background:rgba(31,35,40,0.92);border:1px solid #343a42;" +
    "border-radius:6px;z-index:5";
  const play = el("button", { id: "replay-play", title: "Play / pause (Space)" }, "Play");
  const slider = el("input", { id: "replay-seek", type: "range", min: "0", max: "1", step: "0.05", value: "0" });
  slider.style.flex = "1";
  const label = el("span", { id: "replay-time", class: "mono" }, "0.0 / 0.0 s");
  const speed = el("select", { id: "replay-speed", title: "Playback speed" });
  bar.append(play, slider, label, speed);
  document.getElementById("view").appendChild(bar);
  const badge = document.getElementById("conn");
  // app.js disables every input of a read-only viewer; the timeline is not a command.
  const keepEnabled = new MutationObserver(() => {
    for (const c of [play, slider, speed]) if (c.disabled) c.disabled = false;
  });
  for (const c of [play, slider, speed]) keepEnabled.observe(c, { attributes: true, attributeFilter: ["disabled"] });

  async function control(body) {
    const res = await fetch("/api/replay", {
      method: body ? "POST" : "GET",
      headers: { "Content-Type": "application/json" },
      body: body ? JSON.stringify(body) : undefined,
    });
    if (res.ok) show(await res.json());
  }

  function show(st) {
    R.status = st;
    play.textContent = st.playing ? "Pause" : "Play";
    slider.max = String(st.duration_s);
    if (!R.dragging) slider.value = String(st.t_s);
    label.textContent = `${st.t_s.toFixed(1)} / ${st.duration_s.toFixed(1)} s`;
    if (!speed.options.length) {
      speed.innerHTML = st.speeds.map((s) => `<option value="${s}">${s}x</option>`).join("");
    }
    speed.value = String(st.speed);
  }

  play.addEventListener("click", () => control({ playing: !(R.status && R.status.playing) }));
  slider.addEventListener("input", () => { R.dragging = true; control({ seek_s: Number(slider.value) }); });
  slider.addEventListener("change", () => { R.dragging = false; control({ seek_s: Number(slider.value) }); });
  speed.addEventListener("change", () => control({ speed: Number(speed.value) }));
  // Space plays and pauses here (in the live UI it is the e-stop): catch it first.
  window.addEventListener("keydown", (ev) => {
    if (ev.code === "Space" && ev.target.tagName !== "INPUT") {
      ev.preventDefault(); ev.stopImmediatePropagation();
      play.click();
    }
  }, true);

  // The frames carry the playback position: follow them instead of polling.
  setInterval(() => {
    const S = window.swarmpark && window.swarmpark.S;
    const f = S && S.frame;
    if (f && f.replay && R.status) {
      show({ ...R.status, t_s: f.replay.t_s, playing: !f.sim.paused, speed: f.sim.speed });
    }
    if (badge && badge.textContent === "live") badge.textContent = "replay";
  }, 100);

  window.swarmpark.replay = { control, R };
  control();
})();
