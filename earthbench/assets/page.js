(function () {
  function key(row, i) {
    var c = row.cells[i];
    if (c.hasAttribute('data-v')) {
      var s = c.getAttribute('data-v');
      return s === '' ? null : parseFloat(s);
    }
    return c.textContent.trim().toLowerCase();
  }
  function sortBy(th) {
    var table = th.closest('table');
    var i = Array.prototype.indexOf.call(th.parentNode.children, th);
    var asc = th.getAttribute('aria-sort') !== 'ascending';
    table.querySelectorAll('th').forEach(function (h) { h.removeAttribute('aria-sort'); });
    th.setAttribute('aria-sort', asc ? 'ascending' : 'descending');
    var body = table.tBodies[0];
    var rows = Array.prototype.slice.call(body.rows);
    var keyed = rows.map(function (r, n) { return [key(r, i), n, r]; });
    keyed.sort(function (a, b) {
      var x = a[0], y = b[0];
      if (x === null && y === null) return a[1] - b[1];
      if (x === null) return 1;
      if (y === null) return -1;
      var d = typeof x === 'number' && typeof y === 'number' ? (x < y ? -1 : x > y ? 1 : 0)
                                                          : String(x).localeCompare(String(y));
      return (asc ? d : -d) || a[1] - b[1];
    });
    var frag = document.createDocumentFragment();
    keyed.forEach(function (k) { frag.appendChild(k[2]); });
    body.appendChild(frag);
  }
  document.querySelectorAll('table.sortable th').forEach(function (th) {
    th.addEventListener('click', function () { sortBy(th); });
  });
  // filters: a row shows when every chosen value matches its data-KEY attribute
  document.querySelectorAll('.filters').forEach(function (bar) {
    var section = bar.closest('section');
    function apply() {
      var want = {};
      bar.querySelectorAll('select').forEach(function (s) { if (s.value) want[s.getAttribute('data-key')] = s.value; });
      section.querySelectorAll('table.sortable tbody tr').forEach(function (tr) {
        var show = Object.keys(want).every(function (k) {
          return !tr.hasAttribute('data-' + k) || tr.getAttribute('data-' + k) === want[k];
        });
        tr.classList.toggle('hidden', !show);
      });
    }
    bar.querySelectorAll('select').forEach(function (s) { s.addEventListener('change', apply); });
  });
})();
