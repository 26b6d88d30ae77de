// See terrain.html. Query parameters: ?exaggeration=2 (vertical), ?time=ISO-8601 (the sun's
// position for the lighting; the default is an afternoon sun over Hawaii, low enough to shade
// relief anywhere near the tropics).
/* global Cesium */
const params = new URLSearchParams(location.search);
const fail = (msg) => {
  window.errors.push(msg);
  window.failed = msg;
};

try {
  // No Cesium ion: no imagery, no geocoder, no ion terrain. The token is never used.
  Cesium.Ion.defaultAccessToken = 'unused';
  const layer = await (await fetch('/tiles/layer.json')).json();
  const [west, south, east, north] = layer.bounds ?? [-180, -90, 180, 90];

  const terrainProvider = await Cesium.CesiumTerrainProvider.fromUrl('/tiles/', {
    requestVertexNormals: true,
    requestWaterMask: true,
  });
  terrainProvider.errorEvent.addEventListener((e) => window.errors.push(`terrain provider: ${e.message}`));

  const viewer = new Cesium.Viewer('globe', {
    baseLayer: false,
    terrainProvider,
    geocoder: false,
    baseLayerPicker: false,
    timeline: false,
    animation: false,
    homeButton: false,
    sceneModePicker: false,
    navigationHelpButton: false,
    fullscreenButton: false,
    infoBox: false,
    selectionIndicator: false,
    skyBox: false,
    skyAtmosphere: false,
    shouldAnimate: false,
    showRenderLoopErrors: false,
  });
  // A test page, not an app: the credits (the Cesium ion logo) would only add pixels to the
  // blank check.
  viewer.cesiumWidget.creditContainer.style.display = 'none';
  const { scene } = viewer;
  const { globe } = scene;
  scene.renderError.addEventListener((_, e) => fail(`render error: ${e?.stack ?? e}`));
  scene.backgroundColor = Cesium.Color.fromCssColorString('#0b1020');
  if (scene.sun) scene.sun.show = false;
  if (scene.moon) scene.moon.show = false;
  scene.fog.enabled = false;
  globe.baseColor = Cesium.Color.fromCssColorString('#b8a27a');
  globe.showGroundAtmosphere = false;
  globe.enableLighting = true;
  globe.depthTestAgainstTerrain = true;
  scene.verticalExaggeration = Number(params.get('exaggeration') ?? 2);
  viewer.clock.currentTime = Cesium.JulianDate.fromIso8601(params.get('time') ?? '2024-03-20T01:30:00Z');
  viewer.clock.shouldAnimate = false;

  // Heights through Cesium's own decoder: a 24 × 24 grid over the bounds at the finest zoom.
  const grid = [];
  for (let j = 0; j < 24; j++) {
    for (let i = 0; i < 24; i++) {
      grid.push(Cesium.Cartographic.fromDegrees(west + ((i + 0.5) / 24) * (east - west), south + ((j + 0.5) / 24) * (north - south)));
    }
  }
  await Cesium.sampleTerrainMostDetailed(terrainProvider, grid, true);
  const hs = grid.map((c) => c.height).filter(Number.isFinite);
  const minH = Math.min(...hs);
  const maxH = Math.max(...hs);
  // Frame the samples that rise above the lowest tenth of the range (the land, not the sea).
  const high = grid.filter((c) => c.height > minH + 0.1 * (maxH - minH));
  const deg = Cesium.Math.toDegrees;
  const box = high.length
    ? high.reduce((b, c) => [Math.min(b[0], deg(c.longitude)), Math.min(b[1], deg(c.latitude)), Math.max(b[2], deg(c.longitude)), Math.max(b[3], deg(c.latitude))],
      [Infinity, Infinity, -Infinity, -Infinity])
    : [west, south, east, north];
  const cx = (box[0] + box[2]) / 2;
  const cy = (box[1] + box[3]) / 2;
  const metresPerDegree = 111320;
  const extent = Math.max((box[2] - box[0]) * Math.cos(Cesium.Math.toRadians(cy)), box[3] - box[1], 0.05) * metresPerDegree;
  const target = Cesium.Cartesian3.fromDegrees(cx, cy, minH + 0.3 * (maxH - minH));
  viewer.camera.lookAt(target, new Cesium.HeadingPitchRange(Cesium.Math.toRadians(-20), Cesium.Math.toRadians(-35), 1.3 * extent));
  viewer.camera.lookAtTransform(Cesium.Matrix4.IDENTITY);

  window.stats = {
    bounds: [west, south, east, north],
    sampled: hs.length,
    sampledMinHeight: minH,
    sampledMaxHeight: maxH,
    framed: box,
  };

  // Ready when every tile the view needs has loaded and it stays so for 2 s of frames.
  let stable = 0;
  let frames = 0;
  scene.postRender.addEventListener(() => frames++);
  const started = performance.now();
  const timer = setInterval(() => {
    stable = globe.tilesLoaded ? stable + 1 : 0;
    if (stable >= 8 && frames > 10) {
      clearInterval(timer);
      window.stats.frames = frames;
      window.stats.loadSeconds = (performance.now() - started) / 1000;
      // Private API, for the report only.
      const rendered = globe._surface?._tilesToRender ?? [];
      window.stats.tilesRendered = rendered.length;
      window.stats.levelsRendered = [...new Set(rendered.map((t) => t.level))].sort((a, b) => a - b);
      // Two more frames so the screenshot has the final state.
      requestAnimationFrame(() => requestAnimationFrame(() => { window.ready = true; }));
    }
  }, 250);
} catch (e) {
  fail(`terrain page: ${e?.stack ?? e}`);
}
