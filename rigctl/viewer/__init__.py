"""``rigctl view``: the take's light field in a browser, rendered on the GPU (WebGL2) by the same method as
``rigctl.render``; a local web server (``server``) hands the page one binary bundle per frame set
(``bundle``), and the page's GLSL ES 3.0 shaders (``static/shaders``) do the rest."""
