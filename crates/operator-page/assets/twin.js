// The 3D twin: the part at its nominal pose (ghost) and aligned pose (solid), the touches coloured
// by signed residual with their approach lines, the next suggested touch with its approach, and the robot (its URDF's primitives, or a line
// through its joints) with the ball at its TCP, moving live. The robot base frame is z-up, in
// metres.
import * as THREE from './vendor/three.module.min.js';

const GHOST = new THREE.MeshStandardMaterial({ color: 0x6b7280, transparent: true, opacity: 0.25, depthWrite: false });
const ALIGNED = new THREE.MeshStandardMaterial({ color: 0x16a34a, transparent: true, opacity: 0.8 });
const ROBOT = new THREE.MeshStandardMaterial({ color: 0xf97316 });
const ROBOT_SHAPE = new THREE.MeshStandardMaterial({ color: 0xf97316, roughness: 0.6 });
const BALL = new THREE.MeshStandardMaterial({ color: 0xfacc15 });
const UNALIGNED_TOUCH = new THREE.Color(0x9ca3af);
// Drawn through everything: the place to touch next is often on a face the view does not show.
const NEXT_TOUCH = new THREE.MeshStandardMaterial({ color: 0x7c3aed, emissive: 0x3b0764, depthTest: false, transparent: true });

// URDF's rpy: R = Rz(yaw) Ry(pitch) Rx(roll), three.js's Euler order 'ZYX'.
function poseMatrix(pose) {
  const rotation = new THREE.Euler(pose.rpy[0], pose.rpy[1], pose.rpy[2], 'ZYX');
  return new THREE.Matrix4().compose(
    new THREE.Vector3(...pose.xyz),
    new THREE.Quaternion().setFromEuler(rotation),
    new THREE.Vector3(1, 1, 1),
  );
}

// Blue (inside) through white to red (outside), saturating at `scale_m`.
function residualColour(distance_m, scale_m) {
  const t = Math.max(-1, Math.min(1, distance_m / scale_m));
  const white = new THREE.Color(0xffffff);
  return t < 0 ? white.lerp(new THREE.Color(0x2563eb), -t) : white.lerp(new THREE.Color(0xdc2626), t);
}

// A cylinder from a to b (unit cylinder along y, scaled and turned into place).
function placeLink(mesh, a, b) {
  const direction = new THREE.Vector3().subVectors(b, a);
  const length = direction.length();
  mesh.visible = length > 1e-6;
  if (!mesh.visible) return;
  mesh.position.copy(a).addScaledVector(direction, 0.5);
  mesh.scale.set(1, length, 1);
  mesh.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), direction.normalize());
}

export function createTwin(canvas) {
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xe5e7eb);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x444444, 2.0));
  const sun = new THREE.DirectionalLight(0xffffff, 1.5);
  sun.position.set(2, -3, 4);
  scene.add(sun);
  const grid = new THREE.GridHelper(2, 20, 0x9ca3af, 0xd1d5db);
  grid.rotation.x = Math.PI / 2; // the grid lies in the base's xy plane
  scene.add(grid);
  scene.add(new THREE.AxesHelper(0.2));

  const camera = new THREE.PerspectiveCamera(45, 1, 0.01, 50);
  camera.up.set(0, 0, 1);
  const view = { target: new THREE.Vector3(0.5, 0, 0.2), distance: 2.2, azimuth: -0.9, elevation: 0.5 };

  const parts = new THREE.Group();
  const touches = new THREE.Group();
  const robot = new THREE.Group();
  scene.add(parts, touches, robot);
  let ghost = null;
  let aligned = null;
  let tipRadius = 0.003;
  const links = [];
  const linkGeometry = new THREE.CylinderGeometry(0.025, 0.025, 1, 16);
  const jointGeometry = new THREE.SphereGeometry(0.035, 16, 12);
  const ball = new THREE.Mesh(new THREE.SphereGeometry(1, 20, 14), BALL);
  const tool = new THREE.Mesh(new THREE.CylinderGeometry(0.008, 0.008, 1, 12), ROBOT);
  ball.visible = false;
  tool.visible = false;
  robot.add(ball, tool);

  function updateCamera() {
    const c = Math.cos(view.elevation);
    camera.position.set(
      view.target.x + view.distance * c * Math.cos(view.azimuth),
      view.target.y + view.distance * c * Math.sin(view.azimuth),
      view.target.z + view.distance * Math.sin(view.elevation),
    );
    camera.lookAt(view.target);
  }

  function render() {
    const width = canvas.clientWidth;
    const height = canvas.clientHeight;
    if (canvas.width !== Math.floor(width * renderer.getPixelRatio()) || canvas.height !== Math.floor(height * renderer.getPixelRatio())) {
      renderer.setSize(width, height, false);
      camera.aspect = width / Math.max(1, height);
      camera.updateProjectionMatrix();
    }
    updateCamera();
    renderer.render(scene, camera);
  }
  let pending = false;
  function redraw() {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; render(); });
  }
  new ResizeObserver(redraw).observe(canvas);

  // Drag to turn around the part, pinch or wheel to zoom: enough for a tablet.
  const pointers = new Map();
  let pinch = null;
  canvas.addEventListener('pointerdown', (e) => { canvas.setPointerCapture(e.pointerId); pointers.set(e.pointerId, [e.clientX, e.clientY]); });
  canvas.addEventListener('pointerup', (e) => { pointers.delete(e.pointerId); pinch = null; });
  canvas.addEventListener('pointercancel', (e) => { pointers.delete(e.pointerId); pinch = null; });
  canvas.addEventListener('pointermove', (e) => {
    if (!pointers.has(e.pointerId)) return;
    const [x, y] = pointers.get(e.pointerId);
    pointers.set(e.pointerId, [e.clientX, e.clientY]);
    if (pointers.size === 1) {
      view.azimuth -= (e.clientX - x) * 0.01;
      view.elevation = Math.max(-1.5, Math.min(1.5, view.elevation + (e.clientY - y) * 0.01));
    } else if (pointers.size === 2) {
      const [a, b] = [...pointers.values()];
      const spread = Math.hypot(a[0] - b[0], a[1] - b[1]);
      if (pinch) view.distance = Math.max(0.1, Math.min(20, view.distance * pinch / spread));
      pinch = spread;
    }
    redraw();
  });
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    view.distance = Math.max(0.1, Math.min(20, view.distance * Math.exp(e.deltaY * 0.001)));
    redraw();
  }, { passive: false });

  // The robot's own primitives, one group per link, posed by each robot event.
  const linkGroups = new Map();
  function addRobotShapes(shapes) {
    for (const shape of shapes) {
      let group = linkGroups.get(shape.link);
      if (!group) {
        group = new THREE.Group();
        group.visible = false;
        linkGroups.set(shape.link, group);
        robot.add(group);
      }
      const [a, b, c] = shape.size_m;
      let geometry;
      if (shape.kind === 'box') geometry = new THREE.BoxGeometry(a, b, c);
      else if (shape.kind === 'sphere') geometry = new THREE.SphereGeometry(a, 20, 14);
      else if (shape.kind === 'capsule') geometry = new THREE.CapsuleGeometry(a, c, 8, 20);
      else geometry = new THREE.CylinderGeometry(a, a, c, 24);
      // URDF cylinders and capsules lie along z, three.js's along y.
      if (shape.kind === 'cylinder' || shape.kind === 'capsule') geometry.rotateX(Math.PI / 2);
      const mesh = new THREE.Mesh(geometry, ROBOT_SHAPE);
      mesh.position.set(...shape.xyz);
      mesh.quaternion.set(...shape.quaternion);
      group.add(mesh);
    }
  }

  function setScene(doc) {
    addRobotShapes(doc.robot_shapes || []);
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.Float32BufferAttribute(doc.part.vertices.flat(), 3));
    geometry.setIndex(doc.part.triangles.flat());
    geometry.computeVertexNormals();
    tipRadius = Math.max(doc.tip_radius_m, 0.002);
    ghost = new THREE.Mesh(geometry, GHOST);
    ghost.matrixAutoUpdate = false;
    ghost.matrix.copy(poseMatrix(doc.nominal_pose));
    aligned = new THREE.Mesh(geometry, ALIGNED);
    aligned.matrixAutoUpdate = false;
    aligned.visible = false;
    const edges = new THREE.LineSegments(new THREE.EdgesGeometry(geometry, 30), new THREE.LineBasicMaterial({ color: 0x374151 }));
    ghost.add(edges);
    parts.add(ghost, aligned);
    view.target.set(...doc.nominal_pose.xyz);
    // Close enough that the part and the touches fill the view; the arm reaches in from the side.
    const size_m = new THREE.Box3().setFromBufferAttribute(geometry.attributes.position).getSize(new THREE.Vector3()).length();
    view.distance = Math.max(0.5, 3 * size_m + 0.3);
    redraw();
  }

  function setState(state, residuals, result) {
    touches.clear();
    const values = [...residuals.values()].map(Math.abs);
    const scale = Math.max(1e-4, ...values);
    const sphere = new THREE.SphereGeometry(Math.max(tipRadius, 0.006), 16, 12);
    for (const touch of state.touches) {
      const colour = residuals.has(touch.id) ? residualColour(residuals.get(touch.id), scale) : UNALIGNED_TOUCH;
      const marker = new THREE.Mesh(sphere, new THREE.MeshStandardMaterial({ color: colour }));
      const centre = new THREE.Vector3(...touch.ball_centre_m);
      marker.position.copy(centre);
      const start = centre.clone().addScaledVector(new THREE.Vector3(...touch.approach), -0.08);
      const line = new THREE.Line(new THREE.BufferGeometry().setFromPoints([start, centre]), new THREE.LineBasicMaterial({ color: 0x1f2937 }));
      touches.add(marker, line);
    }
    const next = state.results ? state.results.next_touch : null;
    if (next) {
      const point = new THREE.Vector3(...next.point_mm).multiplyScalar(0.001);
      const approach = new THREE.Vector3(...next.approach).normalize();
      // Larger than a touch, and its arrow longer than their approach lines: it is the one to find.
      const target = new THREE.Mesh(new THREE.SphereGeometry(Math.max(2 * tipRadius, 0.012), 20, 14), NEXT_TOUCH);
      target.position.copy(point);
      const length = 0.15;
      const arrow = new THREE.ArrowHelper(approach, point.clone().addScaledVector(approach, -length), length, 0x7c3aed, 0.04, 0.02);
      for (const material of [arrow.line.material, arrow.cone.material]) {
        material.depthTest = false;
        material.transparent = true;
      }
      target.renderOrder = arrow.renderOrder = arrow.line.renderOrder = arrow.cone.renderOrder = 10;
      touches.add(target, arrow);
    }
    if (aligned) {
      const pose = result && result.current ? (result.command === 'align' ? result.report.pose : result.report.pose_after) : null;
      aligned.visible = Boolean(pose);
      if (pose) aligned.matrix.copy(poseMatrix(pose));
    }
    redraw();
  }

  function setRobot(pose) {
    const shaped = (pose.links || []).filter((link) => linkGroups.has(link.link));
    for (const link of shaped) {
      const group = linkGroups.get(link.link);
      group.visible = true;
      group.position.set(...link.xyz);
      group.quaternion.set(...link.quaternion);
    }
    const points = pose.joints_m.map((p) => new THREE.Vector3(...p));
    while (links.length < points.length) {
      const link = new THREE.Mesh(linkGeometry, ROBOT);
      const joint = new THREE.Mesh(jointGeometry, ROBOT);
      links.push({ link, joint });
      robot.add(link, joint);
    }
    // Without the robot's own shapes, a line through its joints stands for it.
    points.forEach((point, i) => {
      links[i].joint.position.copy(point);
      links[i].joint.visible = shaped.length === 0;
      if (i + 1 < points.length && shaped.length === 0) placeLink(links[i].link, point, points[i + 1]);
      else links[i].link.visible = false;
    });
    const tcp = new THREE.Vector3(...pose.tcp_m);
    ball.visible = true;
    ball.position.copy(tcp);
    ball.scale.setScalar(Math.max(tipRadius, 0.004));
    tool.visible = true;
    placeLink(tool, points[points.length - 1], tcp);
    redraw();
  }

  redraw();
  return { setScene, setState, setRobot };
}
