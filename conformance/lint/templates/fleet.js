// lint --serve: every second, fetch the page's fragment (made and escaped on the server) and
// swap it in. Read-only: GET requests, nothing else.
(function () {
  "use strict";
  var live = document.getElementById("live");
  if (!live || !live.dataset.fragment) { return; }
  var busy = false;
  function poll() {
    if (busy || document.hidden) { return; }
    busy = true;
    fetch(live.dataset.fragment, { cache: "no-store" })
      .then(function (r) { return r.ok ? r.text() : null; })
      .then(function (html) {
        if (html !== null) {
          live.innerHTML = html;
          live.dataset.updated = String(Number(live.dataset.updated || 0) + 1);
        }
      })
      .catch(function () { /* lint has stopped: keep what is shown */ })
      .then(function () { busy = false; });
  }
  setInterval(poll, 1000);
})();
