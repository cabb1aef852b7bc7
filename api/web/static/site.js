// One site, live: its status and result arrive as server-sent events
// (GET /v1/sites/{site}/events) and are drawn without reloading the page.
"use strict";

(() => {
  const ROBOTS_REFRESH_MS = 5000;
  const siteId = decodeURIComponent(window.location.pathname.split("/").filter(Boolean).pop());
  const sitePath = `v1/sites/${encodeURIComponent(siteId)}`;
  const $ = (id) => document.getElementById(id);
  const state = { status: null, result: null, choice: 0 };
  const view3d = View3D.create($("view3d"));
  let gltfGeneration = null;

  document.title = `Floorplan-Jigsaw: ${siteId}`;
  $("site-id").textContent = siteId;

  function emptyStatus() {
    return { site_id: siteId, fragments: [], placement: { state: "idle", progress: 0 }, robots: [] };
  }

  // ---------------------------------------------------------------- rendering

  function renderSummary() {
    const placement = state.status?.placement || {};
    const status = state.result?.status || placement.result_status || "";
    const badge = $("result-status");
    badge.textContent = status || "none yet";
    badge.className = `badge status-${status}`;
    const confidence = state.result ? state.result.confidence : placement.confidence;
    $("confidence").textContent = confidence === null || confidence === undefined ? "–" : confidence.toFixed(2);
    $("placement-state").textContent = placement.state || "idle";
    const stage = placement.state === "running" ? `${placement.stage} ${FPJ.percent(placement.progress)}` : "";
    $("placement-stage").textContent = stage;
  }

  function renderPlacement() {
    const placement = state.status?.placement || {};
    const rows = [
      ["state", placement.state],
      ["stage", placement.stage ? `${placement.stage} (${FPJ.percent(placement.progress)})` : ""],
      ["result status", placement.result_status || ""],
      ["confidence", placement.confidence === null || placement.confidence === undefined ? "" : placement.confidence.toFixed(2)],
      ["alternatives", String(placement.alternatives ?? 0)],
      ["loop closed", placement.loop_closed ? "yes" : "no"],
      ["last placement", FPJ.when(placement.last_placement_at)],
      ["error", placement.error ? `${placement.error.code}: ${placement.error.message}` : ""],
    ];
    $("placement").replaceChildren(
      ...rows.filter(([, value]) => value).flatMap(([name, value]) => [FPJ.el("dt", {}, name), FPJ.el("dd", {}, value)]),
    );
  }

  function placedIds() {
    if (!state.result) return new Map();
    const fragments = state.choice > 0 ? state.result.alternatives[state.choice - 1]?.fragments || [] : state.result.fragments;
    return new Map(fragments.map((f) => [f.id, state.choice > 0 ? Boolean(f.pose) : f.placed]));
  }

  function renderFragments() {
    const fragments = state.status?.fragments || [];
    const placed = placedIds();
    const rows = fragments.map((f) => {
      const progress = FPJ.el("progress", { max: "1", value: String(f.progress) });
      const stateText = f.error ? `${f.state} (${f.error.code})` : f.state;
      const placedText = placed.has(f.fragment_id) ? (placed.get(f.fragment_id) ? "yes" : "no") : "";
      return FPJ.el(
        "tr",
        { "data-fragment": f.fragment_id, title: f.error ? f.error.message : "" },
        FPJ.el("td", {}, FPJ.el("span", { class: "swatch", style: `background:${FPJ.fragmentColor(f.fragment_id)}` })),
        FPJ.el("td", {}, f.fragment_id),
        FPJ.el("td", { class: "state" }, stateText),
        FPJ.el("td", {}, progress, FPJ.el("span", { class: "muted" }, ` ${f.stage}`)),
        FPJ.el("td", { class: "placed" }, placedText),
      );
    });
    $("fragments").querySelector("tbody").replaceChildren(...rows);
    $("fragments-note").textContent = fragments.length ? `${fragments.length} fragment(s)` : "no fragment yet: drop files below";
  }

  function renderRobots() {
    const robots = state.status?.robots || [];
    const items = robots.map((r) =>
      FPJ.el("li", { "data-robot": r.robot_id }, `${r.robot_id}: connected since ${FPJ.when(r.connected_since)}, sent ${r.fragments.length ? r.fragments.join(", ") : "nothing here yet"}`),
    );
    $("robots").replaceChildren(...(items.length ? items : [FPJ.el("li", { class: "muted" }, "none connected")]));
  }

  function renderAlternatives() {
    const box = $("alternatives");
    const result = state.result;
    const alternatives = result?.alternatives || [];
    box.hidden = !(result && result.status === "ambiguous" && alternatives.length);
    if (box.hidden) {
      state.choice = 0;
      box.replaceChildren();
      return;
    }
    const choices = [["most probable", result.confidence], ...alternatives.map((a, k) => [`alternative ${k + 1}`, a.probability])];
    box.replaceChildren(
      FPJ.el("span", {}, "ambiguous: "),
      ...choices.map(([name, probability], k) => {
        const button = FPJ.el("button", { type: "button", "data-choice": String(k), class: k === state.choice ? "active" : "" }, `${name} (p = ${probability.toFixed(2)})`);
        button.addEventListener("click", () => {
          state.choice = k;
          renderResult();
        });
        return button;
      }),
    );
  }

  function renderPlan() {
    const drawn = Plan.draw($("plan"), state.result, state.choice);
    const result = state.result;
    let note = "nothing placed yet";
    if (result) {
      const unplaced = result.fragments.filter((f) => !f.placed).map((f) => f.id);
      note = `${drawn} fragment(s) drawn` + (unplaced.length && state.choice === 0 ? `; not placed: ${unplaced.join(", ")}` : "");
      if (state.choice > 0) note += `; showing alternative ${state.choice}`;
    }
    $("plan-note").textContent = note;
  }

  function renderResult() {
    if (state.result && state.choice > (state.result.alternatives || []).length) state.choice = 0;
    renderAlternatives();
    renderPlan();
    renderSummary();
    renderFragments();
    refresh3d();
  }

  function renderAll() {
    renderSummary();
    renderPlacement();
    renderFragments();
    renderRobots();
    renderResult();
  }

  async function refresh3d() {
    const generation = state.status?.placement?.result_generation ?? null;
    if (!$("view3d-panel").open || !state.result || generation === gltfGeneration) return;
    gltfGeneration = generation;
    const reply = await FPJ.api(`${sitePath}/layout.gltf`);
    view3d.show(reply.status === 200 ? await reply.json() : null);
  }

  // ---------------------------------------------------------------- live updates

  function upsertFragment(event) {
    if (!state.status) state.status = emptyStatus();
    const fragments = state.status.fragments;
    const index = fragments.findIndex((f) => f.fragment_id === event.fragment_id);
    if (event.data.deleted) {
      if (index >= 0) fragments.splice(index, 1);
    } else if (index >= 0) {
      fragments[index] = event.data;
    } else {
      fragments.push(event.data);
    }
    renderFragments();
  }

  const handlers = {
    status(status) {
      state.status = status;
      renderAll();
    },
    fragment: upsertFragment,
    placement(event) {
      if (!state.status) state.status = emptyStatus();
      state.status.placement = event.data;
      renderSummary();
      renderPlacement();
    },
    result(event) {
      state.result = event.data;
      if (state.status && event.generation != null) state.status.placement.result_generation = event.generation;
      renderResult();
    },
    site() {
      state.status = emptyStatus();
      state.result = null;
      renderAll();
      $("plan-note").textContent = "the site was deleted";
    },
  };

  function setLive(mode) {
    const badge = $("live");
    badge.textContent = mode;
    badge.className = `badge live-${mode}`;
    if (mode === "closed") {
      refreshRobots(); // shows the token form if the service refused the token
      window.setTimeout(connect, 5000);
    }
  }

  let source = null;
  function connect() {
    if (source) source.close();
    source = FPJ.events(`${sitePath}/events`, handlers, setLive);
  }

  // Robots are not in the event stream: their list comes with the site's status.
  async function refreshRobots() {
    const reply = await FPJ.api(sitePath).catch(() => null);
    if (!reply || reply.status !== 200) return;
    const status = await reply.json();
    if (!state.status) state.status = emptyStatus();
    state.status.robots = status.robots;
    renderRobots();
  }

  // ---------------------------------------------------------------- uploads and downloads

  function stem(name) {
    const dot = name.lastIndexOf(".");
    return dot > 0 ? name.slice(0, dot) : name;
  }

  async function upload(file) {
    const id = stem(file.name);
    const item = FPJ.el("li", { "data-upload": id }, `${id}: uploading ${file.size} bytes…`);
    $("uploads").prepend(item);
    try {
      const reply = await FPJ.api(`${sitePath}/fragments/${encodeURIComponent(id)}`, {
        method: "PUT",
        body: file,
        headers: { "Content-Type": "application/octet-stream" },
      });
      const body = await reply.json();
      item.textContent = reply.ok
        ? `${id}: ${reply.status === 202 ? "accepted" : "already stored"} (${body.n_points} points)`
        : `${id}: refused, HTTP ${reply.status} ${body.error?.code}: ${body.error?.message}`;
      item.className = reply.ok ? "ok" : "error";
    } catch (error) {
      item.textContent = `${id}: failed (${error.message})`;
      item.className = "error";
    }
  }

  function uploadAll(files) {
    for (const file of files) upload(file);
  }

  const drop = $("drop");
  drop.addEventListener("dragover", (event) => {
    event.preventDefault();
    drop.classList.add("over");
  });
  drop.addEventListener("dragleave", () => drop.classList.remove("over"));
  drop.addEventListener("drop", (event) => {
    event.preventDefault();
    drop.classList.remove("over");
    uploadAll(event.dataTransfer.files);
  });
  $("file-input").addEventListener("change", (event) => {
    uploadAll(event.target.files);
    event.target.value = "";
  });

  async function download(path, suffix) {
    const reply = await FPJ.api(`${sitePath}/${path}`);
    if (reply.status !== 200) {
      $("download-note").textContent = reply.status === 202 ? "nothing placed yet" : `HTTP ${reply.status}`;
      return;
    }
    const link = FPJ.el("a", { href: URL.createObjectURL(await reply.blob()), download: `${siteId}-${suffix}` });
    document.body.append(link);
    link.click();
    link.remove();
    $("download-note").textContent = "";
  }

  for (const button of document.querySelectorAll("[data-download]")) {
    button.addEventListener("click", () => download(button.dataset.download, button.dataset.suffix));
  }
  $("view3d-panel").addEventListener("toggle", () => {
    gltfGeneration = null;
    refresh3d();
  });

  FPJ.tokenForm(() => {
    connect();
    refreshRobots();
  });
  state.status = emptyStatus();
  renderAll();
  connect();
  window.setInterval(refreshRobots, ROBOTS_REFRESH_MS);
})();
