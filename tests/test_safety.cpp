// The primitives every tool uses to keep the user's files safe: the advisory lock, the output
// checks, the unique temporary names, the interrupt flag.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <set>

#include "base/env.h"
#include "base/error.h"
#include "base/file_lock.h"
#include "base/interrupt.h"
#include "base/output_path.h"
#include "test_support.h"

using namespace mt;
using mt::test::TempDir;

TEST(FileLock, SecondHolderIsRefusedWithThePid) {
  TempDir tmp;
  const std::string lock = tmp.file("LOCK");
  {
    FileLock held(lock, "store S");
    EXPECT_EQ(FileLock::holder(lock), long(getpid()));
    // flock locks belong to the open file description: a second open in this process conflicts
    // just as another process would.
    try {
      FileLock second(lock, "store S");
      FAIL() << "second lock taken";
    } catch (const Error& e) {
      std::string m = e.what();
      EXPECT_NE(m.find("store S: in use by process " + std::to_string(getpid())), std::string::npos) << m;
    }
  }
  EXPECT_FALSE(mt::test::fileExists(lock)) << "the lock file is removed on release";
  EXPECT_EQ(FileLock::holder(lock), 0);
  FileLock again(lock, "store S");  // free again
}

TEST(FileLock, DeadHolderDoesNotBlock) {
  TempDir tmp;
  const std::string lock = tmp.file("LOCK");
  pid_t child = fork();
  if (child == 0) {
    FileLock held(lock, "x");
    held.keepFile();
    _exit(0);  // dies holding it: the kernel releases the lock, the file stays
  }
  int status = 0;
  waitpid(child, &status, 0);
  EXPECT_TRUE(mt::test::fileExists(lock));
  EXPECT_EQ(FileLock::holder(lock), 0);
  FileLock mine(lock, "x");
}

TEST(OutputPath, RefusesInputsDirectoriesAndMissingFolders) {
  TempDir tmp;
  const std::string in = tmp.file("in.ply");
  mt::test::writeFile(in, "ply\n");
  EXPECT_THROW(checkOutputPath(in, {in}), Error);
  EXPECT_THROW(checkOutputPath(tmp.path() + "/./in.ply", {in}), Error);
  ASSERT_EQ(::link(in.c_str(), tmp.file("hard.ply").c_str()), 0);
  EXPECT_THROW(checkOutputPath(tmp.file("hard.ply"), {in}), Error) << "same inode under another name";
  EXPECT_THROW(checkOutputPath(tmp.path(), {in}), Error);
  EXPECT_THROW(checkOutputPath(tmp.file("nope/out.mt"), {in}), Error);
  EXPECT_NO_THROW(checkOutputPath(tmp.file("out.mt"), {in}));
  mt::test::writeFile(tmp.file("old.mt"), "x");
  EXPECT_NO_THROW(checkOutputPath(tmp.file("old.mt"), {in})) << "an earlier output may be replaced";
}

TEST(OutputPath, RegularFileCheckNamesTheKind) {
  TempDir tmp;
  ASSERT_EQ(mkfifo(tmp.file("fifo").c_str(), 0644), 0);
  auto message = [](const std::string& p) {
    try {
      requireRegularFile(p, "an MT file");
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(message(tmp.file("fifo")).find("is a FIFO, not an MT file"), std::string::npos);
  EXPECT_NE(message(tmp.path()).find("is a directory"), std::string::npos);
  EXPECT_NE(message("/dev/null").find("is a character device"), std::string::npos);
  EXPECT_NE(message(tmp.file("missing")).find("no such file"), std::string::npos);
  mt::test::writeFile(tmp.file("f"), "x");
  EXPECT_EQ(message(tmp.file("f")), "");
}

TEST(OutputPath, TempNamesAreUniqueAndBesideTheOutput) {
  std::set<std::string> names;
  for (int i = 0; i < 100; ++i) {
    std::string n = uniqueTempName("/a/b/out.mt");
    EXPECT_EQ(n.rfind("/a/b/out.mt.tmp." + std::to_string(getpid()) + ".", 0), 0u) << n;
    names.insert(n);
  }
  EXPECT_EQ(names.size(), 100u);
}

TEST(Interrupt, SignalBecomesAnExceptionAtTheNextSafePoint) {
  installInterruptHandlers();
  clearInterrupt();
  EXPECT_NO_THROW(checkInterrupt("work"));
  raise(SIGTERM);
  EXPECT_EQ(interruptRequested(), SIGTERM);
  try {
    checkInterrupt("level 3");
    FAIL();
  } catch (const Interrupted& e) {
    EXPECT_EQ(e.signal(), SIGTERM);
    EXPECT_STREQ(e.what(), "level 3: interrupted by SIGTERM");
  }
  clearInterrupt();
}

TEST(ErrorKinds, SayWhatWentWrong) {
  TempDir tmp;
  // The file layer: a failed write is an I/O error.
  FaultInjectionEnv env(Env::Default());
  env.failAfter(FaultInjectionEnv::Op::Write, 1);
  try {
    auto f = env.newWritableFile(tmp.file("w"));
    f->append("x", 1);
    FAIL() << "no injected failure";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Io) << e.what();
  }
  try {
    Env::Default()->newRandomAccessFile(tmp.file("missing"));
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Io) << e.what();
  }
  // A signal.
  clearInterrupt();
  Interrupted stop("work", SIGINT);
  EXPECT_EQ(stop.kind(), ErrorKind::Interrupted);
  // The default: the user's input.
  try {
    fail("in.ply", "vertex 3 has a non-finite coordinate");
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::InvalidInput);
    EXPECT_STREQ(e.what(), "in.ply: vertex 3 has a non-finite coordinate");
  }
  EXPECT_STREQ(errorKindName(ErrorKind::Corruption), "corruption");
}

// The Env calls the MT writer and the checkpoint files use: a positional overwrite, and
// continuing a file at a recorded length.
TEST(Env, WriteAtAndContinueAt) {
  TempDir tmp;
  Env* env = Env::Default();
  const std::string path = tmp.file("f");
  {
    auto f = env->newWritableFile(path);
    f->append("abcdef", 6);
    f->writeAt(0, "XY", 2);
    EXPECT_EQ(f->size(), 6u) << "writeAt does not move the end";
    f->sync();
    f->close();
  }
  EXPECT_EQ(mt::test::readFile(path), "XYcdef");
  {
    auto f = env->newWritableFileAt(path, 3);
    EXPECT_EQ(f->size(), 3u);
    f->append("Z", 1);
    f->close();
  }
  EXPECT_EQ(mt::test::readFile(path), "XYcZ") << "what followed the length is cut off";
  try {
    env->newWritableFileAt(path, 5);
    FAIL() << "continued past the end";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Corruption) << e.what();
    EXPECT_EQ(std::string(e.what()), path + ": cannot continue at byte offset 5: the file has only 4 bytes");
  }
  EXPECT_EQ(mt::test::readFile(path), "XYcZ") << "a refused continue changes nothing";
  auto fresh = env->newWritableFileAt(tmp.file("new"), 0);
  EXPECT_TRUE(env->exists(tmp.file("new"))) << "length 0 creates the file";
  try {
    env->newWritableFileAt(tmp.file("missing"), 1);
    FAIL() << "continued a missing file";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Io) << e.what();
    EXPECT_FALSE(env->exists(tmp.file("missing")));
  }
}

TEST(Env, FaultInjectionFailsTheNthReadWithItsOffset) {
  TempDir tmp;
  const std::string path = tmp.file("r");
  {
    auto f = Env::Default()->newWritableFile(path);
    f->append("0123456789", 10);
    f->close();
  }
  FaultInjectionEnv env(Env::Default());
  auto f = env.newRandomAccessFile(path);
  EXPECT_EQ(f->size(), 10u);
  env.failAfter(FaultInjectionEnv::Op::Read, 2);
  char buf[4] = {};
  f->read(1, 3, buf);
  EXPECT_EQ(std::string(buf, 3), "123");
  try {
    f->read(6, 4, buf);
    FAIL() << "no injected failure";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Io);
    EXPECT_EQ(std::string(e.what()), path + ": injected read failure at byte offset 6");
  }
  EXPECT_TRUE(env.fired());
  EXPECT_EQ(env.reads, 2);
  f->read(6, 4, buf);
  EXPECT_EQ(std::string(buf, 4), "6789");
  // A read past the end is an Io error naming the offset.
  try {
    f->read(8, 4, buf);
    FAIL() << "read past the end";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Io);
    EXPECT_NE(std::string(e.what()).find("byte offset 10"), std::string::npos) << e.what();
  }
}
