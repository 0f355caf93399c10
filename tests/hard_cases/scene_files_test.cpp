// Scenes from strangers: the files a glTF names (external buffers) must be plain files of the declared
// size inside the asset root. Each case builds its own folder tree under a temporary directory: a
// one-triangle scene whose buffer uri is the case's, and the file (or directory, FIFO, symlink) it names.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <fcntl.h>
#include <filesystem>
#include <future>
#include <string>
#include <vector>

#include "cli_support.h"
#include "scene/scene_data.h"
#include "vksonar/scene.h"

namespace vksonar {
namespace {

namespace fs = std::filesystem;
using testing::fresh_test_dir;
using testing::quote;
using testing::read_text;
using testing::remove_test_dir;
using testing::write_text;

constexpr std::size_t kTriangleBytes = 36; // three float xyz positions

std::string triangle_bytes() {
    const float xyz[9] = {10, -1, -1, 10, 1, -1, 10, 0, 1};
    return std::string(reinterpret_cast<const char*>(xyz), sizeof xyz);
}

// A one-triangle scene whose only buffer is `uri`, declared `byte_length` bytes long.
std::string triangle_gltf(const std::string& uri, std::size_t byte_length = kTriangleBytes) {
    return R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                 "min": [10, -1, -1], "max": [10, 1, 1]}],
  "bufferViews": [{"buffer": 0, "byteLength": 36}],
  "buffers": [{"uri": ")" +
           uri + R"(", "byteLength": )" + std::to_string(byte_length) + "}]}";
}

class SceneFiles : public ::testing::Test {
protected:
    void SetUp() override {
        root_ = fresh_test_dir("vksonar_scene_files_");
        fs::create_directories(root_ / "scenes" / "sub");
        fs::create_directories(root_ / "elsewhere");
        write_text(root_ / "elsewhere" / "triangle.bin", triangle_bytes());
    }
    void TearDown() override { remove_test_dir(root_); }

    // Writes scenes/scene.gltf naming `uri` and loads it.
    Result<Scene> load(const std::string& uri, const SceneLoadOptions& options = {},
                       std::size_t byte_length = kTriangleBytes) const {
        write_text(scene(), triangle_gltf(uri, byte_length));
        return Scene::load_gltf(scene().string(), options);
    }
    fs::path scene() const { return root_ / "scenes" / "scene.gltf"; }

    // Refused, one line, naming the scene, the uri and the reason.
    static void expect_refused(const Result<Scene>& r, const std::string& uri, const std::string& reason) {
        ASSERT_FALSE(r.ok()) << uri;
        const std::string& message = r.error().message;
        EXPECT_NE(message.find("scene.gltf"), std::string::npos) << message;
        EXPECT_NE(message.find("uri '" + uri + "'"), std::string::npos) << message;
        EXPECT_NE(message.find(reason), std::string::npos) << message;
        EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    }

    fs::path root_;
};

TEST_F(SceneFiles, ABufferBesideOrBelowTheSceneLoads) {
    write_text(root_ / "scenes" / "triangle.bin", triangle_bytes());
    write_text(root_ / "scenes" / "sub" / "triangle.bin", triangle_bytes());
    for (const std::string uri : {"triangle.bin", "sub/triangle.bin", "sub/../triangle.bin", "sub%2Ftriangle.bin"}) {
        const Result<Scene> r = load(uri);
        ASSERT_TRUE(r.ok()) << uri << ": " << r.error().message;
        EXPECT_EQ(scene_data(r.value()).positions.size(), 9u) << uri;
    }
}

TEST_F(SceneFiles, ADirectoryIsRefusedByName) {
    fs::create_directories(root_ / "scenes" / "textures");
    expect_refused(load("textures"), "textures", "is a directory");
    // The percent-encoded spelling of the same folder, as the fuzzer found it.
    expect_refused(load("%74extures"), "%74extures", "is a directory");
}

TEST_F(SceneFiles, AFifoIsRefusedWithoutBlocking) {
    const fs::path fifo = root_ / "scenes" / "x.bin";
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    auto loading = std::async(std::launch::async, [&] { return load("x.bin"); });
    if (loading.wait_for(std::chrono::seconds(10)) != std::future_status::ready) {
        // The loader blocks in open(): a writer releases it so the test fails instead of hanging.
        const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
        if (fd >= 0) ::close(fd);
        FAIL() << "loading a scene whose buffer is a FIFO did not return within 10 s";
    }
    expect_refused(loading.get(), "x.bin", "is not a regular file");
}

TEST_F(SceneFiles, PathsLeavingTheAssetRootAreRefused) {
    // ".." to a real file of exactly the right size outside the scene's folder.
    expect_refused(load("../elsewhere/triangle.bin"), "../elsewhere/triangle.bin", "lies outside the asset root");
    expect_refused(load("sub/../../elsewhere/triangle.bin"), "sub/../../elsewhere/triangle.bin",
                   "(a wider asset root: --asset-root DIR");
    // A symlink inside the folder to a file outside it.
    fs::create_symlink(root_ / "elsewhere" / "triangle.bin", root_ / "scenes" / "link.bin");
    expect_refused(load("link.bin"), "link.bin", "lies outside the asset root");
    // Absolute paths and URLs, whatever they point at.
    const std::string absolute = (root_ / "elsewhere" / "triangle.bin").string();
    expect_refused(load(absolute), absolute, "is an absolute path");
    expect_refused(load("file://" + absolute), "file://" + absolute, "is not a relative path");
}

TEST_F(SceneFiles, TheAssetRootWidensToAParentFolder) {
    SceneLoadOptions parent;
    parent.asset_root = root_.string();
    for (const std::string uri : {"../elsewhere/triangle.bin"}) {
        const Result<Scene> r = load(uri, parent);
        ASSERT_TRUE(r.ok()) << uri << ": " << r.error().message;
        EXPECT_EQ(scene_data(r.value()).positions.size(), 9u);
    }
    fs::create_symlink(root_ / "elsewhere" / "triangle.bin", root_ / "scenes" / "link.bin");
    EXPECT_TRUE(load("link.bin", parent).ok());
    // Still not beyond the widened root, and a root that is not a folder is named.
    SceneLoadOptions scenes_only;
    scenes_only.asset_root = (root_ / "scenes").string();
    expect_refused(load("../elsewhere/triangle.bin", scenes_only), "../elsewhere/triangle.bin", "lies outside");
    SceneLoadOptions missing;
    missing.asset_root = (root_ / "nowhere").string();
    const Result<Scene> r = load("../elsewhere/triangle.bin", missing);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("asset root '" + missing.asset_root + "' is not a folder"), std::string::npos)
        << r.error().message;
}

TEST_F(SceneFiles, ASizeOtherThanByteLengthIsRefusedBeforeItIsRead) {
    write_text(root_ / "scenes" / "big.bin", triangle_bytes() + std::string(1000, '\0'));
    expect_refused(load("big.bin"), "big.bin", "is 1036 bytes, byteLength says 36");
    // A declared size past what vksonar reads is refused by the declaration alone.
    write_text(root_ / "scenes" / "triangle.bin", triangle_bytes());
    expect_refused(load("triangle.bin", {}, std::size_t(3) << 30), "triangle.bin", "over the 2 GiB limit");
}

// The CLI: exit 2 naming the uri and nothing written; the same scene renders once --asset-root names
// the parent.
TEST_F(SceneFiles, TheCliRefusesAndAcceptsWithAssetRoot) {
    write_text(scene(), triangle_gltf("../elsewhere/triangle.bin"));
    const fs::path out = root_ / "out";
    auto render = [&](const std::string& extra) {
        const std::string command = std::string(VKSONAR_CLI) + " render --backend cpu --set range_min=6 --scene " +
                                    quote(scene().string()) + " --out " + quote(out.string()) + extra + " 2>" +
                                    quote((root_ / "err.txt").string()) + " >/dev/null";
        const int status = std::system(command.c_str());
        return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    };
    EXPECT_EQ(render(""), 2);
    const std::string err = read_text(root_ / "err.txt");
    EXPECT_NE(err.find("uri '../elsewhere/triangle.bin' lies outside the asset root"), std::string::npos) << err;
    EXPECT_FALSE(fs::exists(out));
    EXPECT_EQ(render(" --asset-root " + quote(root_.string())), 0) << read_text(root_ / "err.txt");
    EXPECT_TRUE(fs::exists(out / "polar.npy"));
    fs::remove_all(out);
    EXPECT_EQ(render(" --set scene.asset_root=" + quote(root_.string())), 0) << read_text(root_ / "err.txt");
}

} // namespace
} // namespace vksonar
