// MathJax for the equations of the theory pages (Material for MkDocs' MathJax route):
// pymdownx.arithmatex (generic: true) wraps $...$ and $$...$$ into spans of class
// "arithmatex" with \(...\) and \[...\] delimiters, and only those spans are typeset.
window.MathJax = {
  tex: {
    inlineMath: [["\\(", "\\)"]],
    displayMath: [["\\[", "\\]"]],
    processEscapes: true,
    processEnvironments: true
  },
  options: {
    ignoreHtmlClass: ".*|",
    processHtmlClass: "arithmatex"
  }
};

// Typeset again after each page change of Material's instant navigation.
document$.subscribe(() => {
  MathJax.startup.output.clearCache()
  MathJax.typesetClear()
  MathJax.texReset()
  MathJax.typesetPromise()
})
