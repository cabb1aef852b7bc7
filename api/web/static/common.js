// Shared by the pages of the web view: API calls with the bearer token, the event stream,
// fragment colours and small DOM helpers. No dependency, no build step.
"use strict";

const FPJ = (() => {
  const TOKEN_KEY = "fpj-token";
  const root = document.querySelector('meta[name="fpj-root"]')?.content || ".";

  // A token given as ?token=... is kept in localStorage and removed from the address bar.
  function takeTokenFromAddress() {
    const address = new URL(window.location.href);
    if (!address.searchParams.has("token")) return;
    setToken(address.searchParams.get("token"));
    address.searchParams.delete("token");
    window.history.replaceState(null, "", address.pathname + address.search + address.hash);
  }

  function token() {
    return window.localStorage.getItem(TOKEN_KEY) || "";
  }

  function setToken(value) {
    if (value) window.localStorage.setItem(TOKEN_KEY, value);
    else window.localStorage.removeItem(TOKEN_KEY);
  }

  function url(path) {
    return new URL(`${root}/${path}`, window.location.href);
  }

  let onAuthProblem = () => {};

  async function api(path, options = {}) {
    const headers = new Headers(options.headers || {});
    if (token()) headers.set("Authorization", `Bearer ${token()}`);
    const reply = await fetch(url(path), { ...options, headers });
    if (reply.status === 401 || reply.status === 403) onAuthProblem(await errorCode(reply));
    return reply;
  }

  // The error code of a reply, read from a copy so that the caller can still read the body.
  async function errorCode(reply) {
    try {
      return (await reply.clone().json()).error.code;
    } catch {
      return `HTTP ${reply.status}`;
    }
  }

  // EventSource cannot send headers: the token goes as ?access_token=, which the service
  // accepts on the event stream only.
  function events(path, handlers, onState) {
    const address = url(path);
    if (token()) address.searchParams.set("access_token", token());
    const source = new EventSource(address);
    source.onopen = () => onState("live");
    source.onerror = () => onState(source.readyState === EventSource.CLOSED ? "closed" : "reconnecting");
    for (const [kind, handler] of Object.entries(handlers)) {
      source.addEventListener(kind, (event) => handler(JSON.parse(event.data)));
    }
    return source;
  }

  // The colour of a fragment from its id alone, as api/colors.py computes it: FNV-1a of the
  // UTF-8 bytes, murmur3's finalizer, hue = hash mod 360, lightness by bit 16, saturation 70 %.
  function idHash(text) {
    let value = 0x811c9dc5;
    for (const byte of new TextEncoder().encode(text)) {
      value = Math.imul(value ^ byte, 0x01000193) >>> 0;
    }
    value = (value ^ (value >>> 16)) >>> 0;
    value = Math.imul(value, 0x85ebca6b) >>> 0;
    value = (value ^ (value >>> 13)) >>> 0;
    value = Math.imul(value, 0xc2b2ae35) >>> 0;
    return (value ^ (value >>> 16)) >>> 0;
  }

  function channel(m1, m2, hue) {
    hue = ((hue % 1) + 1) % 1;
    if (hue * 6 < 1) return m1 + (m2 - m1) * hue * 6;
    if (hue * 2 < 1) return m2;
    if (hue * 3 < 2) return m1 + (m2 - m1) * (2 / 3 - hue) * 6;
    return m1;
  }

  function fragmentColor(id) {
    const value = idHash(id);
    const hue = (value % 360) / 360;
    const lightness = [0.36, 0.46][(value >>> 16) & 1];
    const m2 = lightness * (0.7 + 1);
    const m1 = lightness * 2 - m2;
    const rgb = [1 / 3, 0, -1 / 3].map((shift) => Math.floor(channel(m1, m2, hue + shift) * 255 + 0.5));
    return "#" + rgb.map((c) => c.toString(16).padStart(2, "0")).join("");
  }

  function el(tag, attributes = {}, ...children) {
    const node = document.createElement(tag);
    for (const [name, value] of Object.entries(attributes)) {
      if (value !== undefined && value !== null) node.setAttribute(name, value);
    }
    for (const child of children) node.append(child);
    return node;
  }

  function svg(tag, attributes = {}, text) {
    const node = document.createElementNS("http://www.w3.org/2000/svg", tag);
    for (const [name, value] of Object.entries(attributes)) node.setAttribute(name, value);
    if (text !== undefined) node.textContent = text;
    return node;
  }

  function when(iso) {
    return iso ? new Date(iso).toLocaleString() : "";
  }

  function percent(value) {
    return value === null || value === undefined ? "" : `${Math.round(value * 100)} %`;
  }

  // The token form of the page header: shown when the service asks for a token.
  function tokenForm(onSaved) {
    const form = document.getElementById("token-form");
    const input = document.getElementById("token-input");
    const note = document.getElementById("token-note");
    document.getElementById("token-toggle").addEventListener("click", () => {
      form.hidden = !form.hidden;
    });
    form.addEventListener("submit", (event) => {
      event.preventDefault();
      setToken(input.value.trim());
      input.value = "";
      form.hidden = true;
      onSaved();
    });
    const problems = {
      unauthorized: "this service needs a token",
      forbidden: "the token was refused",
      insufficient_scope: "this token may not do that on this site (its sites and rights)",
    };
    onAuthProblem = (code) => {
      form.hidden = false;
      note.textContent = problems[code] || `the token was refused (${code})`;
    };
  }

  takeTokenFromAddress();
  return { api, events, fragmentColor, el, svg, token, setToken, tokenForm, url, when, percent };
})();
