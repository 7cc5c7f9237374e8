#!/usr/bin/env bash
# Fetches the parts of the "unseen" CAD corpora (docs/cad-scan-trials.md): robot links that no
# setting of the project was tuned on before they were scanned, from robots that appear nowhere
# else here. Set A: PAL Robotics' TIAGo Pro arm and torso, Unitree's Z1 arm, Franka's Panda
# collision meshes (it showed the local stage's first failure on parts of others, and the change
# that followed was chosen on it). Set B, held out: Universal Robots' UR5 collision meshes,
# Unitree's G1 humanoid and Agility's Cassie, looked at once, after that change was chosen.
# Set C, held out from the fifteenth session on: PAL Robotics' TALOS arm, Willow Garage's PR2 arm
# and Unitree's Go2 leg (collision hulls), scanned with both peers once the changes that session
# made on the other sets were chosen.
# Set D, held out until the thirty-seventh session: IIT's Centauro arm (its millimetre meshes
# written in metres), ODRI's Solo12 leg and base and Bolt body, Unitree's Laikago leg.
# Set E, held out until the forty-second session: PAL Robotics' TIAGo (the first one: arm, head,
# torso), ODRI's FingerEdu links and Wonik's Allegro hand (its base and thumb link, 41-114 mm).
# Set F, held out until the forty-eighth session: IHMC's Alexander humanoid (every link of its
# left leg in the wheel, and its pelvis: Blender OBJ files of quads), the double pendulum's base
# and first link and the Hector quadrotor's frame (790 mm across, 15 bodies).
# Set G, held out until the forty-ninth session: Kinova's Gen3 arm, Rethink's Sawyer arm and
# Boston Dynamics' Spot leg and arm link, from another source (robosuite) and other exporters.
# Sets A-F come from the PyPI wheel example-robot-data 6.0.0 (the wheel the shipped xArm7 and
# SO-ARM100 meshes came from), set G from the PyPI wheel robosuite 1.5.2. They are written,
# checked by SHA-256, into one folder per robot under OUT (default target/unseen-parts); nothing
# is copied into the repository.
#
#   bash scripts/unseen-parts.sh [OUT]
#   target/release/cad-scans --scans 40 --ips local --seed 64 \
#       --mesh-dir OUT/tiago_pro --mesh-dir OUT/z1 --mesh-dir OUT/panda \
#       --parts tiago_pro_,z1_,panda_ --out DIR          # set A
#   (set B: --mesh-dir OUT/ur5 --mesh-dir OUT/g1 --mesh-dir OUT/cassie --parts ur5_,g1_,cassie_;
#    set C: --mesh-dir OUT/talos --mesh-dir OUT/pr2 --mesh-dir OUT/go2 --parts talos_,pr2_,go2_;
#    set D: --mesh-dir OUT/centauro --mesh-dir OUT/solo12 --mesh-dir OUT/bolt
#           --mesh-dir OUT/laikago --parts centauro_,solo12_,bolt_,laikago_;
#    set E: --mesh-dir OUT/tiago --mesh-dir OUT/finger_edu --mesh-dir OUT/allegro_hand
#           --parts tiago_,finger_edu_,allegro_hand_ --no-peers;
#    set F: --mesh-dir OUT/alexander --mesh-dir OUT/double_pendulum --mesh-dir OUT/hector
#           --parts alexander_,double_pendulum_,hector_;
#    set G: --mesh-dir OUT/kinova3 --mesh-dir OUT/sawyer --mesh-dir OUT/spot
#           --parts kinova3_,sawyer_,spot_)
#
# Licenses, as the wheel's README of each description names them (panda_description also
# carries its LICENSE file): tiago_pro Apache-2.0, z1 MPL-2.0, panda Apache-2.0, ur BSD,
# g1 BSD-3-Clause, cassie ISC, talos_data Apache-2.0, pr2 BSD, go2 MPL-2.0, centauro Apache-2.0,
# solo BSD-3-Clause, bolt BSD-3-Clause, laikago MPL-2.0, tiago Apache-2.0, finger_edu
# BSD-3-Clause, allegro_hand BSD, alexander Apache-2.0 (its LICENSE file is in the wheel),
# double_pendulum BSD, hector BSD; robosuite (set G) is MIT (its LICENSE file is in the wheel)
# and ships these robots' meshes among its assets; the wheel names no other license for them,
# and their upstreams' own terms were not checked here. They are only read here, never shipped.
# (The example-robot-data wheel's Alex upper body is CC-BY-NC-ND-4.0 and is left out.)
# Idempotent: files already in place with the right hash are kept.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:-target/unseen-parts}"
DOWNLOADS="target/unseen-parts-wheel"
mkdir -p "$OUT" "$DOWNLOADS"
# The wheel of a PyPI distribution, downloaded once: fetch_wheel NAME VERSION
fetch_wheel() {
    local file_prefix="${1//-/_}-$2-"
    if ! ls "$DOWNLOADS"/"$file_prefix"*.whl >/dev/null 2>&1; then
        python3 -m pip download --quiet --disable-pip-version-check --no-deps \
            "$1==$2" -d "$DOWNLOADS"
    fi
    ls "$DOWNLOADS"/"$file_prefix"*.whl | head -1
}
ROBOT_DATA_WHEEL="$(fetch_wheel example-robot-data 6.0.0)"
ROBOSUITE_WHEEL="$(fetch_wheel robosuite 1.5.2)"
python3 - "$ROBOT_DATA_WHEEL" "$ROBOSUITE_WHEEL" "$OUT" <<'EOF'
import hashlib, os, struct, sys, zipfile

robot_data_wheel, robosuite_wheel, out = sys.argv[1], sys.argv[2], sys.argv[3]
# path in the wheel (after ".../robots/"), file written under OUT, its SHA-256
ROBOT_DATA_PARTS = [
    ("tiago_pro_description/meshes/arm_tiago_pro/arm_1_link.stl", "tiago_pro/arm_1_link.stl",
     "8f3672dbbb71d5ff9a158f687eb4438de0455b8aa73c92e9bb64f6aa50cfcd38"),
    ("tiago_pro_description/meshes/arm_tiago_pro/arm_2_link.stl", "tiago_pro/arm_2_link.stl",
     "96ce7ed57708af6d2b3586dc4ec07d175a7d6025e9848f75539ef80d99b59375"),
    ("tiago_pro_description/meshes/arm_tiago_pro/arm_6_link.stl", "tiago_pro/arm_6_link.stl",
     "b17826b37b80a57831ff11da67adbb539b5144d8213a43bf8dac34749a4b878a"),
    ("tiago_pro_description/meshes/torso/torso_lift_link.stl", "tiago_pro/torso_lift_link.stl",
     "98922a8c4c2b4e2ba57e9109faef69fa2a8288fd403912935da67ddf07df759c"),
    ("z1_description/meshes/collision/z1_Link02.STL", "z1/link02.stl",
     "f9c01aa32fd77fb2b3504b2225842ba348d13d17afeee9a2b28e9856feaac762"),
    ("z1_description/meshes/collision/z1_Link03.STL", "z1/link03.stl",
     "c1f70986e916438710718004e820b0298fda86590a30e3de79b0c54876c84141"),
    ("z1_description/meshes/collision/z1_Link04.STL", "z1/link04.stl",
     "93ec60a1583cfcf95ba7fbeb917eb8b860fbd6e146c2be3c3b98b083b7a5b505"),
    ("panda_description/meshes/collision/link1.stl", "panda/link1.stl",
     "e41a39a94108fcf56aacff603fc91ec80541f4c1af17b51a0de5617f5566e6d2"),
    ("panda_description/meshes/collision/link3.stl", "panda/link3.stl",
     "0a8d638b9349c6c0eefc4e888636ac4838c4b27170f18a51699321118af709c1"),
    ("panda_description/meshes/collision/link5.stl", "panda/link5.stl",
     "dd17e688c7870e722283525879643d53a74c0024d328b0e14b034b54c8b6c31a"),
    # Set B, held out: looked at once, after the changes set A led to were chosen.
    ("ur_description/meshes/ur5/collision/upperarm.stl", "ur5/upperarm.stl",
     "55c11ac0ad1e144f230849b2033532e8b140b2e818ea497296d08dfb88757440"),
    ("ur_description/meshes/ur5/collision/forearm.stl", "ur5/forearm.stl",
     "8e79aa80a532494ba5320c30b40363ff63d228e3d59e2904703dca341dcba2ac"),
    ("ur_description/meshes/ur5/collision/shoulder.stl", "ur5/shoulder.stl",
     "1d62e23a8c3ff9e6334fb157c805e6202037bcfca65bc6a36c5c9ae866751b3b"),
    ("ur_description/meshes/ur5/collision/wrist1.stl", "ur5/wrist1.stl",
     "0a1fd12150140efdee91650dcb4c2d0443065551a9207a2d2dbde58ff1fb4eb7"),
    ("g1_description/meshes/left_knee_link.STL", "g1/left_knee_link.stl",
     "8d92b9e3d3a636761150bb8025e32514c4602b91c7028d523ee42b3e632de477"),
    ("g1_description/meshes/torso_link_rev_1_0.STL", "g1/torso_link.stl",
     "ac5f569f123d872a7b48f58c1fb986a0aa09942a980be04df3e2f975b1a33e78"),
    ("g1_description/meshes/left_hip_yaw_link.STL", "g1/left_hip_yaw_link.stl",
     "a16d88aa6ddac8083aa7ad55ed317bea44b1fa003d314fba88965b7ed0f3b55b"),
    ("cassie_description/meshes/pelvis.stl", "cassie/pelvis.stl",
     "717625c1cd2738831d3bd69a3f75b90f8416a4d4da38250820b64cc4c5538dca"),
    ("cassie_description/meshes/hip-pitch.stl", "cassie/hip_pitch.stl",
     "2cbf3f004697508286be5cf2684b6e1251c019cc51bd5a816fa44882798ccc70"),
    ("cassie_description/meshes/tarsus.stl", "cassie/tarsus.stl",
     "890913b018136cbd3d015745263e764e69df3e2aa371f3e7bea9cd7a9d682a12"),
    # Set C, held out: scanned once, after the fifteenth session's changes were chosen.
    ("talos_data/meshes/arm/arm_1.stl", "talos/arm_1.stl",
     "520e084533a0a0e90aafadb1dd1b0fa4f646b12dac8df691030d768e328a92e5"),
    ("talos_data/meshes/arm/arm_2.stl", "talos/arm_2.stl",
     "e55c0a0eaba43f37b44a6ea3be2037366cae8c34fd06293b3dcf4730a982c9ca"),
    ("talos_data/meshes/arm/arm_3.stl", "talos/arm_3.stl",
     "f22ac1f25dd54805810b05362a62aaa690f49e21ce7adb8ff921ba07f9f2257d"),
    ("talos_data/meshes/arm/arm_5.stl", "talos/arm_5.stl",
     "e7bacaff657c70c84f18130a8c6c74404244a63f220d61d1c9b05cfa0dbb1981"),
    ("pr2_description/meshes/upper_arm_v0/upper_arm.stl", "pr2/upper_arm.stl",
     "823a410be7cfea0440309a585f9a11d30d4e387ff5674f90eb9e0526729e05b6"),
    ("pr2_description/meshes/forearm_v0/forearm.stl", "pr2/forearm.stl",
     "3dab89b1fc8a76569b88d917684a05f59015c6325478c88296ded14bac08cbf0"),
    ("pr2_description/meshes/upper_arm_v0/elbow_flex.stl", "pr2/elbow_flex.stl",
     "af7438c914bffa6bfbdc7c218fed06f512fc4a0739992a05496fdd9c0f7116e7"),
    ("go2_description/collisions/thigh_convex.stl", "go2/thigh.stl",
     "79e1a4e04a4ffa8e6ea248b36beefed2381768f54b97b182f78fdc9cab391264"),
    ("go2_description/collisions/calf_upper_convex.stl", "go2/calf_upper.stl",
     "912bf59fe55daef8e56ba4529bc3988d9f4c53b0cd298f31ca49530bfc1e1a6e"),
    ("go2_description/collisions/hip_convex.stl", "go2/hip.stl",
     "e90792c60b892c57834a0beb0b340c6da812175e7a37dfc679693e1a59222929"),
    # Set D, held out: first scanned in the thirty-seventh session, after every setting then in
    # place had been chosen. Centauro's meshes are in millimetres (its URDF scales them by
    # 0.001): they are written in metres.
    ("centauro_description/meshes/Elbow.STL", "centauro/elbow.stl",
     "d63293d5ab439b39d60f486051b86bd65b328f797e85c276a41848f21b51459f", 0.001),
    ("centauro_description/meshes/Forearm.STL", "centauro/forearm.stl",
     "a82348678c5e4650228d93ad372e05de3ce46d846eb0f2bda16be35881b85756", 0.001),
    ("centauro_description/meshes/ShoulderYaw.STL", "centauro/shoulder_yaw.stl",
     "24afe9453e3df49126d22702608b1c6a538a8da90dd820c2bde276dd1985bed1", 0.001),
    ("solo_description/meshes/stl/solo12/solo12_upper_leg_left_side.stl", "solo12/upper_leg.stl",
     "2546e8c34cbba4b6a573e013344a68de33ded7735c8f66d3b44b8ffe91d15287"),
    ("solo_description/meshes/stl/solo12/solo12_lower_leg_left_side.stl", "solo12/lower_leg.stl",
     "cb6b8c570d2614991f8e87c3ce3757741e6bec9538c05d0f802abfaaaef3b9eb"),
    ("solo_description/meshes/stl/solo12/solo_12_base.stl", "solo12/base.stl",
     "3c65eb4eeb6a4e52b9ff1e3c53e53c724c8f5d6f0414791864ced79baddd60d7"),
    ("bolt_description/meshes/stl/bolt_body.stl", "bolt/body.stl",
     "6f2129ad7bb67676c2906d017f5eba924693de706ed7be3386e8cfa58b53a38e"),
    ("laikago_description/meshes/calf.obj", "laikago/calf.obj",
     "8aac67b6dc806c21f710b25b38a16d924de82de6ac4ee951e69fa61db03a7e96"),
    ("laikago_description/meshes/thigh.obj", "laikago/thigh.obj",
     "440940425b78ee5c44ecdbea84c514923029f2021adcba255dd8074d85719cc6"),
    ("laikago_description/meshes/hip.obj", "laikago/hip.obj",
     "bf6aef44be84ee64558ee29a3f19450efd8a6a2f65f93d873f6bfc633fcc0b42"),
    # Set E, held out: first scanned in the forty-second session, to check the change that
    # session chose on sets A-D (the fine second look's contenders).
    ("tiago_description/meshes/arm/arm_1.stl", "tiago/arm_1.stl",
     "a98a1becdaa0f17182ae242cbf829c327a108f11bb7dbdf1554ec76d7364c599"),
    ("tiago_description/meshes/arm/arm_2.stl", "tiago/arm_2.stl",
     "df8df6ed235678f8e0b48f99024cb5cd9cea83c0ca6963275fe704f07433f508"),
    ("tiago_description/meshes/arm/arm_3.stl", "tiago/arm_3.stl",
     "7894bc60a7c2b68cdeaa991e9ad03f48abcb5e72f8ffb5a50b1f4edadfb417e9"),
    ("tiago_description/meshes/head/head_2.stl", "tiago/head_2.stl",
     "8cc0b5fc791d313670f5d857cc83df415de6435a7c83d407b112dc6334a33158"),
    ("tiago_description/meshes/torso/torso_lift_without_arm.stl",
     "tiago/torso_lift_without_arm.stl",
     "5abbfad42f064647355ab0246178912e48d800b93ab495584896a1456ccff7e9"),
    ("finger_edu_description/meshes/upper_link.stl", "finger_edu/upper_link.stl",
     "e9979cb210c727b2bb11e303734dd6ba9aa41c19752bdf665754ac2bf50dcae9"),
    ("finger_edu_description/meshes/middle_link.stl", "finger_edu/middle_link.stl",
     "313e6eaede4524245bbd26fafaa5dc165a9a9958a8a5136ea057d1afd5844b87"),
    ("finger_edu_description/meshes/lower_link.stl", "finger_edu/lower_link.stl",
     "a96d1d93473af29a893bef7424b1a27a33d5183edbabbe13f22b77b2164fd106"),
    ("allegro_hand_description/meshes/base_link.STL", "allegro_hand/base_link.stl",
     "4060e1ae52bca21367e15a1dfab16bc7c2e81849566631b7f55e2cf376b7bc85"),
    ("allegro_hand_description/meshes/link_12.0_right.STL", "allegro_hand/link_12_right.stl",
     "c5418fc127311eefee1d8ee69dfcfde2157d038286900bee91608d2701b00f13"),
    # Set F, held out: first scanned in the forty-eighth session, after that session's change
    # (the inside of closed meshes of several bodies) was chosen on sets A-E.
    ("alexander_description/meshes/Pelvis.obj", "alexander/pelvis.obj",
     "56bc72e8aed66ddf3e8aa1bb1aa70d50172f7fd743a419cabb92b24736423b23"),
    ("alexander_description/meshes/LeftHipYawLink.obj", "alexander/left_hip_yaw_link.obj",
     "cc1bc2bceff2e127d1df854776abbba25d6639d9c25c363bb3dfd48d275d3c68"),
    ("alexander_description/meshes/LeftHipRollLink.obj", "alexander/left_hip_roll_link.obj",
     "51615e455465872d2242f139ba61faa6ef3fe26b266b8b89c195b9ce4c561f07"),
    ("alexander_description/meshes/LeftThigh.obj", "alexander/left_thigh.obj",
     "d26309e60f470e512688a9ad85a14909ef9dfad46a206a5e9afa709b30e5b056"),
    ("alexander_description/meshes/LeftShin.obj", "alexander/left_shin.obj",
     "d3cbca8d6d3526cd114a72e7c8b5b64161a7166ec5c770e6248377bb1802f00d"),
    ("alexander_description/meshes/AnklePitchLink.obj", "alexander/ankle_pitch_link.obj",
     "b2fb97a491515b071b828d8b87b035ff3feb988f2e693f283ad9114ddfa2000e"),
    ("alexander_description/meshes/Foot.obj", "alexander/foot.obj",
     "45299cea0bd1fb968d8f77ba84699a0a905e7abe937aceeae3d520bfe4f30c10"),
    ("double_pendulum_description/meshes/base_link.stl", "double_pendulum/base_link.stl",
     "db0f87de6444cd48e83a7ef1c25a55b26a611c3ef97cb3ae342b4bd16478be18"),
    ("double_pendulum_description/meshes/link1.stl", "double_pendulum/link1.stl",
     "bc3b4e2eb378ddc2c9d6a29b4c55dd673a2922ff197dc6b279685b6523564f39"),
    ("hector_description/meshes/quadrotor/quadrotor_base.stl", "hector/quadrotor_base.stl",
     "d2e4f8f6ee307006e687320790263f412d92973a7bf344ad302afb9388866f43"),
]
# Set G, held out: first scanned in the forty-ninth session, on the build of that session's start
# (0779480), with both peers in one run.
ROBOSUITE_PARTS = [
    ("kinova3/meshes/shoulder_link.stl", "kinova3/shoulder_link.stl",
     "a98e232e5197f09e9cd520e7a450c21bcec74bc49e2a19ce7cf86c5dc25f2e18"),
    ("kinova3/meshes/half_arm_1_link.stl", "kinova3/half_arm_1_link.stl",
     "8df461a71780d8e2d09104a507584424279d85173adf14867e359f7e58b3bba7"),
    ("kinova3/meshes/spherical_wrist_1_link.stl", "kinova3/spherical_wrist_1_link.stl",
     "0b97a5e3b2de535344f8e8d4176d77f0cdb3455b235f35430fa0413208856e66"),
    ("sawyer/obj_meshes/l1.obj", "sawyer/l1.obj",
     "6e551d2b6633fa879fe4d4a69d584922205a44ad1ad9a3899736fcc8ae5d8edc"),
    ("sawyer/obj_meshes/l2.obj", "sawyer/l2.obj",
     "974a66e72ae987c1cd7f47fefd4756646e298739a7c879244b2c3ff0533fb19c"),
    ("sawyer/obj_meshes/l5.obj", "sawyer/l5.obj",
     "3e0d0f74383ee20bb4dbbab14dc21233a68458d842c7d972c7f68dc27ce55629"),
    ("spot/meshes/front_left_hip.obj", "spot/front_left_hip.obj",
     "71caaba7f10e75de7b331d1b1d99f57de6fc8fad0dd436aea09de0e256b88b55"),
    ("spot/meshes/front_left_upper_leg_1.obj", "spot/front_left_upper_leg.obj",
     "dba444ac01083909a841a576e5755dab3ba6580c5c2ac1fc870a047fa01bf63d"),
    ("spot/meshes/front_left_lower_leg.obj", "spot/front_left_lower_leg.obj",
     "202a07b4226fba77ce28e053de6524b8407d3206309ffafb96828f09c4c34a1d"),
    ("spot_arm/meshes/arm_link_hr0.obj", "spot/arm_link_hr0.obj",
     "edfdce679d1d0afac6fc2495f81b29b85c5f36edcb9c66ebcb75843f227f8e89"),
]


def scaled_binary_stl(data, scale):
    """A binary STL with every vertex multiplied by scale (normals are unchanged)."""
    (count,) = struct.unpack_from("<I", data, 80)
    if len(data) != 84 + 50 * count:
        sys.exit("unseen-parts: a mesh to scale is not a binary STL")
    out = bytearray(data[:84])
    for i in range(count):
        record = data[84 + 50 * i: 134 + 50 * i]
        values = struct.unpack_from("<12f", record)
        corners = [v * scale for v in values[3:]]
        out += struct.pack("<12f", *values[:3], *corners) + record[48:50]
    return bytes(out)


for wheel, parts in ((robot_data_wheel, ROBOT_DATA_PARTS), (robosuite_wheel, ROBOSUITE_PARTS)):
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
        for inside, target, sha, *scale in parts:
            path = os.path.join(out, target)
            if not scale and os.path.exists(path) \
                    and hashlib.sha256(open(path, "rb").read()).hexdigest() == sha:
                continue
            found = [n for n in names if n.endswith("/robots/" + inside)]
            if len(found) != 1:
                sys.exit(f"unseen-parts: {inside} is not in {wheel} once ({len(found)} matches)")
            data = archive.read(found[0])
            if hashlib.sha256(data).hexdigest() != sha:
                sys.exit(f"unseen-parts: {inside} in {wheel} does not have the expected SHA-256")
            if scale:
                data = scaled_binary_stl(data, scale[0])
                if os.path.exists(path) and open(path, "rb").read() == data:
                    continue
            os.makedirs(os.path.dirname(path), exist_ok=True)
            with open(path, "wb") as f:
                f.write(data)
print(f"unseen-parts: {len(ROBOT_DATA_PARTS) + len(ROBOSUITE_PARTS)} meshes;"
      f" set A in {out}/tiago_pro, {out}/z1, {out}/panda;"
      f" set B in {out}/ur5, {out}/g1, {out}/cassie; set C in {out}/talos, {out}/pr2, {out}/go2;"
      f" set D in {out}/centauro, {out}/solo12, {out}/bolt, {out}/laikago;"
      f" set E in {out}/tiago, {out}/finger_edu, {out}/allegro_hand;"
      f" set F in {out}/alexander, {out}/double_pendulum, {out}/hector;"
      f" set G in {out}/kinova3, {out}/sawyer, {out}/spot")
EOF
