# Sources and targets that cannot be compiled in a unity build (CMAKE_UNITY_BUILD, which
# tests/sanitize.sh turns on for the sanitizer builds; docs/reliability.md, test command time).
# A unity build includes up to 8 of a target's sources into one translation unit, so two of
# them may not define the same name at file scope (anonymous namespace, static, enum). Each
# exception is listed here, in one place, with the name that clashes; a source listed here is
# compiled on its own, a target listed here compiles every source on its own. Included at the
# end of the top-level CMakeLists.txt, after every target exists.

# Generated protobuf code: the target sets UNITY_BUILD OFF itself (proto/CMakeLists.txt).

# C, and cheap to compile: the wire library's files each define OFF_* offset enumerators.
set_target_properties(mocap_wire PROPERTIES UNITY_BUILD OFF)

# mocap_unity_skip(TARGET source...): the sources (relative to the target's directory) are
# compiled on their own in TARGET's unity build.
function(mocap_unity_skip target)
  if(NOT TARGET ${target})  # a test target without MOCAP_TESTS
    return()
  endif()
  get_target_property(dir ${target} SOURCE_DIR)
  foreach(src ${ARGN})
    set_source_files_properties(${dir}/${src} TARGET_DIRECTORY ${target}
                                PROPERTIES SKIP_UNITY_BUILD_INCLUSION ON)
  endforeach()
endfunction()

mocap_unity_skip(mocap_fusion heading_filter.cpp)  # kDeg (chain_estimator.cpp)
mocap_unity_skip(mocap-client output_commands.cpp)  # kExitConnection, kExitFailed (main.cpp)
mocap_unity_skip(mocap-client take_commands.cpp)  # kExitConnection, kExitFailed (main.cpp)
mocap_unity_skip(mocap_client_lib load_client.cpp)  # Clock (pose_client.cpp)
mocap_unity_skip(mocap_client_lib load_stream_client.cpp)  # Clock (pose_client.cpp)
mocap_unity_skip(mocap_chain_sim pendulum_scenario.cpp)  # kDeg, kPi (chain_scenario.cpp)
mocap_unity_skip(mocap_stream_sim stream_node.cpp)  # kDeg (stream_motion.cpp)
mocap_unity_skip(mocap_cluster raw_stream.cpp)  # kApiWaitMs, steady_us (calibration_bucket.cpp)
mocap_unity_skip(mocap_serve_http pose_json.cpp)  # dump (http_takes.cpp)
mocap_unity_skip(mocap_skeleton calibration.cpp)  # rot_z (body_chain.cpp)
mocap_unity_skip(clients_chain_tests pendulum_scenario_test.cpp)  # kDeg, kGravityUp, vec (chain_scenario_test.cpp)
mocap_unity_skip(clients_stream_tests magnetic_env_test.cpp)  # kDeg (stream_node_test.cpp)
mocap_unity_skip(filter_tests mahony_test.cpp)  # still (madgwick_test.cpp)
mocap_unity_skip(filter_tests mocap_filter_test.cpp)  # still (madgwick_test.cpp)
mocap_unity_skip(fusion_tests hinge_axis_estimator_test.cpp)  # axis_angle, kDeg, rz (chain_estimator_test.cpp)
mocap_unity_skip(fusion_tests joint_position_estimator_test.cpp)  # axis_angle (chain_estimator_test.cpp)
mocap_unity_skip(cluster_faults_tests cluster_faults_test.cpp)  # kSite, kUser (cluster_ha_test.cpp)
mocap_unity_skip(cluster_integration_tests cluster_auth_test.cpp)  # kSite (cluster_test.cpp)
mocap_unity_skip(serve_http_tests http_takes_test.cpp)  # Fixture (http_server_test.cpp)
mocap_unity_skip(serve_outputs_tests record_disk_full_test.cpp)  # publish_frames (bvh_recorder_test.cpp)
mocap_unity_skip(skeleton_tests calibration_test.cpp)  # deg, random_quat (bvh_test.cpp)
mocap_unity_skip(skeleton_tests joint_angles_test.cpp)  # deg (bvh_test.cpp)
mocap_unity_skip(skeleton_tests pose_smoother_test.cpp)  # deg (bvh_test.cpp)
mocap_unity_skip(wire_tests packet_test.cpp)  # encode (keepalive_test.cpp)
mocap_unity_skip(math_tests markley_average_test.cpp)    # random_quat, qdist (quaternion_test.cpp)
