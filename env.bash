# The workspace's environment, for a shell (`source env.bash`) and for the Makefile: the venv
# (the ROS 2 Jazzy wheels and mows), the venv prefix on AMENT_PREFIX_PATH so that the ament
# index finds the wheels' interfaces (std_msgs, sensor_msgs, ... for `ros2 interface show` and
# rosidl), and the built packages (install/, after `make build`).
_mows_root=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
source "$_mows_root/.venv/bin/activate"
case ":${AMENT_PREFIX_PATH:-}:" in
    *":$VIRTUAL_ENV:"*) ;;
    *) export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;;
esac
source "$_mows_root/install/setup.bash"
unset _mows_root
