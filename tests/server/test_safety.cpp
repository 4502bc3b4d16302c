// The server never serves a file outside its root, nor a file that is not a registered dataset.
#include "support.h"

namespace catpaq::test {
namespace {

class Safety : public ServerTest {};

struct Attempt {
    const char* target;
    int status;
};

TEST_F(Safety, TraversalEncodedSeparatorsNulBackslashAndAbsolutePathsAreRefused) {
    const Attempt attempts[] = {
        {"/files/../outside/secret.cpq", 400},
        {"/files/sub/../../outside/secret.cpq", 400},
        {"/files/%2e%2e/outside/secret.cpq", 400},
        {"/files/%2E%2E/outside/secret.txt", 400},
        {"/files/.%2e/outside/secret.cpq", 400},
        {"/files/..%2foutside%2fsecret.cpq", 400},
        {"/files/sub%2fbeta.cpq", 400},
        {"/files/%2Ftmp%2Fsecret.cpq", 400},
        {"/files//etc/passwd", 400},
        {"/files/alpha.cpq%00.txt", 400},
        {"/files/sub%5cbeta.cpq", 400},
        {"/files/sub\\beta.cpq", 400},
        {"/files/./alpha.cpq", 400},
        {"/files/%zz", 400},
        {"/api/datasets/../../outside/secret", 400},
        {"/api/datasets/%2e%2e/outside/secret/prefix", 400},
        {"http://evil.example/files/../outside/secret.cpq", 400},
        {"files/alpha.cpq", 400},
        {"/files/outside/secret.cpq", 404},
        {"/files/escape.cpq", 404},  // symlink resolving outside the root
        {"/api/datasets/escape", 404},
        {"/files/notes.txt", 404},  // inside the root but not a dataset
        {"/files/fake.cpq", 404},   // named like one but not valid
        {"/files/sub", 404},
        {"/files/alpha", 404},
    };
    std::string secret = read_whole_file(fixture->outside() + "/secret.cpq");
    RawClient client(port());
    for (const Attempt& a : attempts) {
        HttpResponse r = client.get(a.target);
        EXPECT_EQ(r.status, a.status) << a.target;
        EXPECT_EQ(r.body.find("CPQARCH"), std::string::npos) << a.target;
        EXPECT_EQ(r.body.find("TOP-SECRET"), std::string::npos) << a.target;
        EXPECT_EQ(r.body.find("notes, not a dataset"), std::string::npos) << a.target;
    }
    // Still serving.
    EXPECT_EQ(client.get("/files/alpha.cpq", "Range: bytes=0-7\r\n").body, "CPQARCH\x1a");
}

TEST_F(Safety, SymlinkPointingOutsideTheRootIsNotRegisteredAndIsLogged) {
    std::vector<std::string> names = running->server->dataset_names();
    EXPECT_EQ(std::find(names.begin(), names.end(), "escape"), names.end());
    EXPECT_TRUE(running->log.contains("escape.cpq", "outside the root"));
    // A symlink to a dataset inside the root is fine.
    EXPECT_NE(std::find(names.begin(), names.end(), "inside_link"), names.end());
}

TEST_F(Safety, AbsoluteFormTargetIsServedLikeItsPath) {
    RawClient client(port());
    HttpResponse r = client.get("http://localhost/api/datasets/alpha");
    EXPECT_EQ(r.status, 200);
    EXPECT_EQ(client.get("/api/datasets/alpha?cache-buster=1").status, 200);  // queries are ignored
}

TEST_F(Safety, PercentEncodedOrdinaryCharactersInNamesAreDecoded) {
    RawClient client(port());
    const BuiltNode& node = fixture->beta[1];
    EXPECT_EQ(client.get("/api/datasets/%73ub/beta/nodes/" + std::to_string(node.key)).body, to_string(node.bytes));
    EXPECT_EQ(client.get("/files/sub/%62eta.cpq", "Range: bytes=0-7\r\n").status, 206);
}

TEST(ServerStartup, MissingRootFailsToStartWithAnError) {
    ServerSettings settings;
    settings.root = "/nonexistent/catpaq/root";
    settings.port = 0;
    settings.log = [](LogLevel, std::string_view) {};
    StreamingServer server(settings);
    EXPECT_THROW(server.start(), std::exception);
}

TEST(ServerStartup, RootThatIsAFileFailsToStart) {
    TempDir dir;
    write_text_file(dir.path() + "/file", "x");
    ServerSettings settings;
    settings.root = dir.path() + "/file";
    settings.port = 0;
    settings.log = [](LogLevel, std::string_view) {};
    StreamingServer server(settings);
    EXPECT_THROW(server.start(), std::exception);
}

TEST(ServerStartup, EmptyRootServesAnEmptyCatalog) {
    TempDir dir;
    RunningServer running(dir.path());
    RawClient client(running.port);
    HttpResponse r = client.get("/api/datasets");
    EXPECT_EQ(r.status, 200);
    EXPECT_EQ(r.body, "{\"datasets\":[]}");
}

}  // namespace
}  // namespace catpaq::test
