// The list of sites (GET /v1/sites), refreshed every few seconds.
"use strict";

(() => {
  const REFRESH_MS = 3000;
  const body = document.querySelector("#sites tbody");
  const note = document.getElementById("sites-note");

  function row(site) {
    const placement = site.placement;
    const link = FPJ.el("a", { href: `sites/${encodeURIComponent(site.site_id)}` }, site.site_id);
    const status = placement.result_status || "";
    return FPJ.el(
      "tr",
      { "data-site": site.site_id },
      FPJ.el("td", {}, link),
      FPJ.el("td", {}, String(site.n_fragments)),
      FPJ.el("td", {}, placement.state),
      FPJ.el("td", {}, FPJ.el("span", { class: `badge status-${status}` }, status || "none yet")),
      FPJ.el("td", {}, FPJ.percent(placement.confidence)),
      FPJ.el("td", {}, FPJ.when(site.updated_at)),
    );
  }

  async function refresh() {
    try {
      const reply = await FPJ.api("v1/sites?limit=1000");
      if (!reply.ok) {
        note.textContent = `cannot list the sites: HTTP ${reply.status}`;
        return;
      }
      const list = await reply.json();
      body.replaceChildren(...list.sites.map(row));
      note.textContent = list.total ? `${list.total} site(s)` : "no site yet";
    } catch (error) {
      note.textContent = `service unreachable (${error.message}); retrying`;
    }
  }

  document.getElementById("open-form").addEventListener("submit", (event) => {
    event.preventDefault();
    const id = document.getElementById("open-input").value.trim();
    if (id) window.location.href = `sites/${encodeURIComponent(id)}`;
  });
  FPJ.tokenForm(refresh);
  refresh();
  window.setInterval(refresh, REFRESH_MS);
})();
