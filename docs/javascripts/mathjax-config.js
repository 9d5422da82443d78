// MathJax 3 settings for pymdownx.arithmatex (generic mode): \( \) inline, \[ \] display, only inside .arithmatex.
// The MathJax script itself is copied into the site from the django-static-mathjax package by docs/mathjax_hook.py,
// so the pages render their mathematics with no network.
window.MathJax = {
  tex: {inlineMath: [["\\(", "\\)"]], displayMath: [["\\[", "\\]"]], processEscapes: true, processEnvironments: true},
  options: {ignoreHtmlClass: ".*|", processHtmlClass: "arithmatex"},
  svg: {fontCache: "global"}
};
