"""Where a script finds the package's tools and files: through the ROS environment first (catkin's
find_in_workspaces over CMAKE_PREFIX_PATH: an install space's lib/liver_sim and share/liver_sim,
or a devel space's lib/liver_sim and its sources), else in the repository layout of
scripts/run.sh (build/ws/devel/lib/liver_sim, the repository's own files).

Installed beside the scripts that import it (lib/liver_sim); a script run through catkin's devel
relay puts its own folder on sys.path first."""
import os

# The repository, when the script runs from it (also through the workspace's links).
REPO = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))


def _in_workspaces(search_dir, path):
    try:
        from catkin.find_in_workspaces import find_in_workspaces
    except ImportError:
        return None
    found = find_in_workspaces([search_dir], project="liver_sim", path=path, first_match_only=True)
    return found[0] if found else None


def tool(name):
    """The built tool `name` (simulate, bench, ...)."""
    return _in_workspaces("libexec", name) or os.path.join(REPO, "build", "ws", "devel", "lib", "liver_sim", name)


def package_file(*parts):
    """The package's file or folder, e.g. package_file("config", "scenes", "liver_phantom.yaml")."""
    relative = os.path.join(*parts)
    return _in_workspaces("share", relative) or os.path.join(REPO, relative)


def package_root():
    """The package's folder (share/liver_sim, or the sources): paths in committed tables are relative to it."""
    return os.path.dirname(package_file("package.xml"))


def output_folder():
    """Where figures and tables go by default: the repository's doc/ (where they are committed) when
    the script runs from the repository, else the current folder."""
    doc = os.path.join(REPO, "doc")
    return doc if os.path.isfile(os.path.join(REPO, "package.xml")) and os.path.isdir(doc) else os.getcwd()
