// trust-av drive: the road as the participant sees it, drawn with Konva (a 2-D canvas scene
// graph, vendored: vendor/README.md). Two views of the same state: the driver's eye (the
// default: the road ahead in perspective, the lead vehicle and the AV's rear with its brake
// lights, speed and gap as dials) and the view from above. The shapes are made once; each
// frame moves them and draws the visible layer (drive.js calls draw at the display's frame
// rate). Everything is laid out on a VIEW_W x VIEW_H stage scaled to the page's width.
'use strict';

window.DriveView = (() => {
  const VIEW_W = 960, VIEW_H = 420;
  const VEHICLE_LENGTH_M = 4.5;
  const BRAKE_LIGHT_MPS2 = -0.3;        // the AV's commanded acceleration that lights them
  const EYE_BEHIND_BUMPER_M = 2.0, EYE_HEIGHT_M = 1.2, CAR_WIDTH_M = 1.8, CAR_HEIGHT_M = 1.5;
  const DASH_EVERY_M = 12, DASH_LENGTH_M = 3, DASH_AHEAD_M = 200, LANE_HALF_M = 1.85;
  const ROAD_HALF_M = 5.5, NEAR_M = 1.0, FAR_M = 600;
  const HORIZON = VIEW_H * 0.40, FOCAL = VIEW_W * 1.1, CX = VIEW_W / 2;   // pinhole, px
  const yAt = (z) => HORIZON + EYE_HEIGHT_M * FOCAL / z;                 // road at distance z
  const xAt = (x, z) => CX + x * FOCAL / z;                             // lateral x (m) at z
  const PLATE_FONT_M = 0.12, PLATE_FONT_MIN_PX = 8;                    // readable from afar
  const TOP_SCALE = 8;                                                  // top-down, px per m

  // A car's rear in metres: origin on the road under the middle of its rear, y up is
  // negative (the group is scaled to px per metre at its distance). Its lamps (to be lit) and
  // plate text come back with it.
  function carRear(colour, label) {
    const group = new Konva.Group();
    const w = CAR_WIDTH_M, h = CAR_HEIGHT_M, left = -w / 2, top = -h;
    group.add(new Konva.Rect({x: left - 0.1, y: -0.05, width: w + 0.2, height: 0.12, fill: '#00000055'}));
    group.add(new Konva.Line({closed: true, fill: colour, points: [
      left, -0.25, left, top + 0.55 * h, left + 0.15 * w, top, left + 0.85 * w, top,
      left + w, top + 0.55 * h, left + w, -0.25]}));
    group.add(new Konva.Rect({x: left + 0.2 * w, y: top + 0.08 * h, width: 0.6 * w, height: 0.32 * h, fill: '#2b3440'}));
    for (const x of [left + 0.05 * w, left + 0.77 * w]) {                // tyres
      group.add(new Konva.Rect({x, y: -0.3, width: 0.18 * w, height: 0.3, fill: '#222'}));
    }
    group.add(new Konva.Rect({x: left, y: -0.45, width: w, height: 0.18, fill: '#3a3a3a'}));   // bumper
    const lampW = 0.22 * w, lampH = 0.12 * h, lampY = top + 0.58 * h;
    const lamps = [
      new Konva.Rect({x: left + 0.02 * w, y: lampY, width: lampW, height: lampH}),
      new Konva.Rect({x: left + w - 0.02 * w - lampW, y: lampY, width: lampW, height: lampH}),
      new Konva.Rect({x: left + 0.42 * w, y: top + 0.02 * h, width: 0.16 * w, height: 0.04 * h}),  // third light
    ];
    lamps.forEach((lamp) => group.add(lamp.setAttrs({fill: '#5e1b1b', shadowColor: '#ff2020', shadowEnabled: false})));
    let plateText = null;
    if (label) {                                                         // the plate
      const plate = {x: left + 0.38 * w, y: lampY + 0.02 * h, width: 0.24 * w, height: 0.1 * h};
      plateText = new Konva.Text({...plate, text: label, fontSize: PLATE_FONT_M, fontStyle: 'bold',
        fontFamily: 'sans-serif', fill: '#0d47a1', align: 'center', verticalAlign: 'middle'});
      group.add(new Konva.Rect({...plate, fill: '#f4f4f4'}), plateText);
    }
    return {group, lamps, plateText};
  }

  // A half dial at the bottom of the windscreen: its face, and a big and a small line of text.
  function dial(layer, x, y, r) {
    layer.add(new Konva.Arc({x, y, innerRadius: 0, outerRadius: r + 12, angle: 180, rotation: 180, fill: '#0e1319ee'}));
    const big = new Konva.Text({x: x - r, y: y - 44, width: 2 * r, align: 'center', fontSize: 24,
      fontStyle: 'bold', fontFamily: 'sans-serif', fill: '#fff'});
    const small = new Konva.Text({x: x - r, y: y - 17, width: 2 * r, align: 'center', fontSize: 12,
      fontFamily: 'sans-serif', fill: '#fff'});
    layer.add(big, small);
    return {big, small};
  }

  function driverLayer() {
    const layer = new Konva.Layer({listening: false});
    layer.add(new Konva.Rect({width: VIEW_W, height: HORIZON, fillLinearGradientStartPoint: {x: 0, y: 0},
      fillLinearGradientEndPoint: {x: 0, y: HORIZON}, fillLinearGradientColorStops: [0, '#5b86b5', 1, '#b9cfe3']}));
    layer.add(new Konva.Rect({y: HORIZON, width: VIEW_W, height: VIEW_H - HORIZON, fill: '#5d7d46'}));
    layer.add(new Konva.Line({closed: true, fill: '#4a4d52', points: [
      xAt(-ROAD_HALF_M, NEAR_M), yAt(NEAR_M), xAt(-ROAD_HALF_M, FAR_M), yAt(FAR_M),
      xAt(ROAD_HALF_M, FAR_M), yAt(FAR_M), xAt(ROAD_HALF_M, NEAR_M), yAt(NEAR_M)]}));
    for (const x of [-5.4, 5.4]) {                                       // road edges
      layer.add(new Konva.Line({stroke: '#e8e8e8', strokeWidth: 2,
        points: [xAt(x, NEAR_M), yAt(NEAR_M), xAt(x, FAR_M), yAt(FAR_M)]}));
    }
    const dashes = [];                                                   // lane dashes: a pool
    for (let i = 0; i < 2 * (Math.ceil(DASH_AHEAD_M / DASH_EVERY_M) + 2); i++) {
      dashes.push(new Konva.Line({closed: true, fill: '#f0f0f0', points: []}));
    }
    layer.add(...dashes);
    const lead = carRear('#8d939b', ''), av = carRear('#dfe3e8', 'AV');
    layer.add(lead.group, av.group);
    layer.add(new Konva.Path({fill: '#1f2a36', data:                     // your bonnet
      `M0 ${VIEW_H} L${VIEW_W * 0.12} ${VIEW_H * 0.86} Q${CX} ${VIEW_H * 0.80} ${VIEW_W * 0.88} ${VIEW_H * 0.86} L${VIEW_W} ${VIEW_H} Z`}));
    const cx = VIEW_W * 0.2, cy = VIEW_H - 12, r = 70;
    const speed = dial(layer, cx, cy, r);
    speed.small.text('km/h');
    for (let v = 0; v <= 160; v += 20) {                                 // km/h ticks
      const a = Math.PI + (v / 160) * Math.PI;
      layer.add(new Konva.Line({stroke: '#9fb3c8', strokeWidth: 2, points: [
        cx + Math.cos(a) * (r - 8), cy + Math.sin(a) * (r - 8), cx + Math.cos(a) * r, cy + Math.sin(a) * r]}));
    }
    const needle = new Konva.Line({x: cx, y: cy, points: [0, 0, r - 6, 0], stroke: '#ff7043', strokeWidth: 4});
    layer.add(needle);
    const gap = dial(layer, VIEW_W * 0.8, cy, r);
    gap.small.text('gap to the AV');
    return {layer, dashes, lead, av, speed, needle, gap};
  }

  function placeCar(car, z, brake) {
    if (z < 0.6) z = 0.6;                     // at (or in) your bumper: drawn at the windscreen
    const px = FOCAL / z;
    car.group.setAttrs({visible: true, x: CX, y: yAt(z), scaleX: px, scaleY: px});
    if (car.plateText) car.plateText.fontSize(Math.max(PLATE_FONT_M, PLATE_FONT_MIN_PX / px));
    for (const lamp of car.lamps) {           // dim red; bright, with a glow, while braking
      lamp.setAttrs({fill: brake > 0 ? '#ff1f1f' : '#5e1b1b', shadowEnabled: brake > 0,
        shadowBlur: (10 + 30 * brake) / px});  // the glow in px (a shadow scales with the car)
    }
  }

  function drawDriver(v, s) {
    const you = s.you[0];
    let i = 0;                                // lane dashes, fixed to the road: they pass by
    for (let k = Math.floor((you - 2) / DASH_EVERY_M); k * DASH_EVERY_M < you + DASH_AHEAD_M; k++) {
      const z0 = k * DASH_EVERY_M - you + EYE_BEHIND_BUMPER_M, z1 = z0 + DASH_LENGTH_M;
      if (z1 <= NEAR_M) continue;
      const a = Math.max(z0, NEAR_M);
      for (const x of [-LANE_HALF_M, LANE_HALF_M]) {
        if (i >= v.dashes.length) break;
        v.dashes[i++].setAttrs({visible: true, points: [xAt(x - 0.08, a), yAt(a), xAt(x - 0.08, z1), yAt(z1),
          xAt(x + 0.08, z1), yAt(z1), xAt(x + 0.08, a), yAt(a)]});
      }
    }
    for (; i < v.dashes.length; i++) v.dashes[i].visible(false);
    const braking = typeof s.avAccel === 'number' && s.avAccel < BRAKE_LIGHT_MPS2;
    const strength = braking ? Math.min(1, 0.5 + (-s.avAccel) / 4) : 0;
    const rear = (x) => x - VEHICLE_LENGTH_M - you + EYE_BEHIND_BUMPER_M;
    if (s.lead) placeCar(v.lead, rear(s.lead[0]), 0); else v.lead.group.visible(false);
    if (s.av) placeCar(v.av, rear(s.av[0]), strength); else v.av.group.visible(false);
    const kmh = s.you[1] * 3.6;
    v.speed.big.text(kmh.toFixed(0));
    v.needle.rotation(180 + Math.min(1, Math.max(0, kmh / 160)) * 180);
    const gap = s.av ? s.av[0] - VEHICLE_LENGTH_M - you : null;
    v.gap.big.text(gap === null ? '' : `${Math.max(0, gap).toFixed(1)} m`);
    v.gap.big.fill(gap !== null && gap < 10 ? '#ffab40' : '#fff');
    v.gap.small.visible(gap !== null);
    v.layer.draw();
  }

  function topLayer() {
    const layer = new Konva.Layer({listening: false, visible: false});
    const mid = VIEW_H / 2;
    layer.add(new Konva.Rect({width: VIEW_W, height: VIEW_H, fill: '#3a3f47'}));
    layer.add(new Konva.Rect({y: mid - 50, width: VIEW_W, height: 100, fill: '#555b64'}));
    const lines = [mid + 50, mid - 50].map((y) => new Konva.Line({
      points: [0, y, VIEW_W, y], stroke: '#ddd', strokeWidth: 3, dash: [30, 30]}));
    layer.add(...lines);
    const cars = {};
    for (const [name, colour, label] of [['lead', '#9e9e9e', 'lead'], ['av', '#1e88e5', 'AV'], ['you', '#fb8c00', 'you']]) {
      const group = new Konva.Group({y: mid});
      group.add(new Konva.Rect({x: -VEHICLE_LENGTH_M * TOP_SCALE, y: -9, width: VEHICLE_LENGTH_M * TOP_SCALE, height: 18, fill: colour}));
      group.add(new Konva.Text({x: -VEHICLE_LENGTH_M * TOP_SCALE, y: -30, text: label, fontSize: 14,
        fontFamily: 'sans-serif', fill: '#fff'}));
      const brake = new Konva.Rect({x: -VEHICLE_LENGTH_M * TOP_SCALE, y: -9, width: 4, height: 18, fill: '#ff1744', visible: false});
      group.add(brake);
      layer.add(group);
      cars[name] = {group, brake};
    }
    return {layer, lines, cars};
  }

  function drawTop(v, s) {
    const origin = VIEW_W * 0.2;
    for (const line of v.lines) line.dashOffset((s.you[0] * TOP_SCALE) % 60);
    for (const name of ['lead', 'av', 'you']) {
      const car = v.cars[name];
      car.group.visible(Boolean(s[name]));
      if (!s[name]) continue;
      car.group.x(origin + (s[name][0] - s.you[0]) * TOP_SCALE);
      car.brake.visible(name === 'av' && typeof s.avAccel === 'number' && s.avAccel < BRAKE_LIGHT_MPS2);
    }
    v.layer.draw();
  }

  // The view in ``container`` (a div): draw(state, topDown) each frame, blank() without one.
  function create(container) {
    const stage = new Konva.Stage({container, width: VIEW_W, height: VIEW_H});
    const driver = driverLayer(), top = topLayer();
    stage.add(driver.layer, top.layer);
    const fit = () => {                         // the stage follows the page's width
      const k = container.clientWidth / VIEW_W;
      if (k > 0 && Math.abs(stage.scaleX() - k) > 1e-3) {
        stage.setAttrs({width: VIEW_W * k, height: VIEW_H * k, scaleX: k, scaleY: k});
      }
    };
    fit();
    window.addEventListener('resize', fit);
    let shown;
    function show(layer) {                      // one layer, or none (the page's background)
      if (shown === layer) return;
      for (const l of [driver.layer, top.layer]) l.visible(l === layer);
      shown = layer;
    }
    show(null);                                 // nothing drawn before the first frame
    return {
      stage, driver, top,
      draw(s, topDown) {
        fit();
        if (topDown) { show(top.layer); drawTop(top, s); } else { show(driver.layer); drawDriver(driver, s); }
      },
      blank() { show(null); },
    };
  }

  return {create, VIEW_W, VIEW_H};
})();
