// netfi ui: what every page's script starts with. Plain script, compiled
// into the binary with the page; it talks only to the server that sent it.
"use strict";

const $ = (id) => document.getElementById(id);

// Every state change is JSON with the page's own header: the server
// refuses anything else, so no other page can make one.
async function call(method, url, body) {
  const init = { method, headers: {}, credentials: "same-origin" };
  if (method !== "GET") {
    init.body = JSON.stringify(body ?? {});
    init.headers["content-type"] = "application/json";
    init.headers["x-netfi-ui"] = "1";
  }
  const res = await fetch(url, init);
  const text = await res.text();
  if (!res.ok) throw new Error(text || res.statusText);
  return text;
}

